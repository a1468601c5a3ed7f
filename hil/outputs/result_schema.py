"""result.json's schema as a pydantic model (docs/contracts.md, "result.json"), exported as JSON Schema to
docs/result.schema.json, and that of a trial of several units' index to docs/units_result.schema.json
(``python -m hil.outputs.result_schema``; a test fails when a committed file differs).
Read a result.json with :func:`read_result`: the model validates it, and callers use its fields."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, ValidationError

SCHEMA_FILE = Path(__file__).resolve().parents[2] / "docs" / "result.schema.json"
UNITS_SCHEMA_FILE = SCHEMA_FILE.with_name("units_result.schema.json")
Vector3 = list[float | None]
Verdict = Literal["PASS", "FAIL", "INTERRUPTED", "ENDED EARLY"]


class _Block(BaseModel):
    model_config = ConfigDict(extra="forbid")


class Trial(_Block):
    name: str
    duration_s: float | None
    samples: int


class DriftCheck(_Block):
    drift_ug_per_h: Vector3 | None
    sigma_ug_per_h: Vector3 | None
    significant: bool


class Estimate(_Block):
    """µg and seconds; with the bias unobservable ``accel_bias_ug`` is null and ``observable`` false."""

    bias_model: str
    accel_bias_ug: Vector3 | None
    accel_bias_sigma_ug: Vector3 | None
    observable: bool
    gram_rank: int
    gram_condition: float | None
    converged_at_s: float | None
    noise_ug: float | None
    drift_check: DriftCheck | None = None
    accel_bias_t0_ug: Vector3 | None = None
    accel_bias_t0_sigma_ug: Vector3 | None = None
    accel_bias_drift_ug_per_h: Vector3 | None = None
    accel_bias_drift_sigma_ug_per_h: Vector3 | None = None
    drift_converged_at_s: float | None = None


class TableReference(_Block):
    accel_bias_ug: Vector3 | None
    accel_bias_sigma_ug: Vector3 | None
    tilt_deg: list[float | None] | None
    accel_bias_drift_ug_per_h: Vector3 | None = None
    accel_bias_drift_sigma_ug_per_h: Vector3 | None = None


class Angles(_Block):
    pitch: float | None
    roll: float | None
    yaw: float | None = None


class Alignment(_Block):
    """Estimate minus turntable reference (deg); null where the trial gave no solution."""

    method1: Angles | None
    method2: Angles | None
    theoretical: Angles | None


class Truth(_Block):
    accel_bias_ug: Vector3
    accel_drift_ug_per_h: Vector3


class CalibrationSummary(_Block):
    file: str
    positions: int
    residual_rms_ug: float | None
    residual_max_ug: float | None
    unobservable: list[str]
    worst_error_sigma: float | None


class Record(_Block):
    dut_part: str | None
    dut_serial: str | None
    station: str | None
    operator: str | None
    notes: str | None
    software_version: str
    commit: str | None
    config_sha256: str | None
    started_utc: str
    ended_utc: str
    host: str
    ports: dict[str, Any] | None
    controller: str | None
    # what the IMU said of its configuration as the trial attached (docs/devices.md, "Configuration check"):
    # {answered, replies, settings}; null when it was not asked
    imu_config: dict[str, Any] | None = None


class Result(_Block):
    """One trial's result.json."""

    trial: Trial
    ended: str
    # PASS or FAIL against output.limits for a completed trial, else how it ended; null: not judged yet
    verdict: Verdict | None = None
    calibration_applied: dict[str, Any] | None
    streams: dict[str, Any]
    estimate: Estimate | None
    table_reference: TableReference | None
    alignment_deg: Alignment | None
    truth: Truth | None = None
    calibration: CalibrationSummary | None = None
    record: Record | None = None


class UnitLine(_Block):
    """A unit's line of the index: where its outputs are, how it ended, its verdict and headline figures (µg, s)."""

    name: str
    out_dir: str | None  # relative to the index's directory: units/<name>; None for an absent unit
    dut_serial: str | None
    ended: str  # "absent: <why>" for an optional unit that was not there
    verdict: Verdict | Literal["ABSENT"]
    accel_bias_ug: Vector3 | None
    accel_bias_sigma_ug: Vector3 | None
    converged_at_s: float | None
    truth_accel_bias_ug: Vector3 | None


class UnitsTrial(_Block):
    name: str


class UnitsResult(_Block):
    """The result.json of a trial of several units (docs/units.md): its index; each unit's own is a :class:`Result`."""

    trial: UnitsTrial
    ended: str
    verdict: Verdict  # the units' worst
    units: list[UnitLine]


def read_result(path: str | Path) -> Result:
    """The result.json at ``path``, validated."""
    return Result.model_validate_json(Path(path).read_bytes())


def result_problem(doc: dict) -> str | None:
    """Why ``doc`` is not a result.json of this version: the first field the schema refuses, as
    ``"<dotted path>: <reason>"``; None when it is one."""
    try:
        Result.model_validate(doc, strict=True)  # a number written as a string is not one
    except ValidationError as exc:
        error = exc.errors()[0]
        return f"{'.'.join(map(str, error['loc'])) or 'the document'}: {error['msg'][:1].lower()}{error['msg'][1:]}"
    return None


def schema_text(model: type[BaseModel] = Result) -> str:
    """The JSON Schema of ``model`` (:class:`Result`, as docs/result.schema.json holds it, or :class:`UnitsResult`,
    as docs/units_result.schema.json does)."""
    return json.dumps(model.model_json_schema(), indent=2) + "\n"


if __name__ == "__main__":  # python -m hil.outputs.result_schema: write both schemas anew
    for path, model in ((SCHEMA_FILE, Result), (UNITS_SCHEMA_FILE, UnitsResult)):
        path.write_text(schema_text(model))
        print(path, file=sys.stderr)
