"""Trial configuration: YAML (safe loading) validated into typed, frozen models.

Units are in the key names (deg, deg/h, ug, ppm, arcsec, s); the rest of the code works in SI and
converts at the edges through the ``*_si`` helpers below. Unknown keys and bad values raise
:class:`ConfigError` naming the key path and the reason, e.g.
``imu.errors.accel_bias_ug: expected 3 numbers, got 2``.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Any, Literal

import yaml
from pydantic import Field, ValidationError, model_serializer, model_validator

from drivers.can_settings import CanConfig
from drivers.registry import IMU_CODECS, TABLE_CODECS, TABLE_CONTROLLERS
from hil.config_emulated import DeviceTiming, FaultConfig, ImuErrors, ImuFaultConfig
from hil.config_environment import EnvironmentConfig, SoakSettings, check_temperatures
from hil.config_ratetests import FrequencyResponseSettings, ScaleFactorSettings
from hil.config_types import ZERO3, Model, Vec2, Vec3, describe_validation
from hil.config_units import UNIT_NAME, check_units, one_unit_only, unit_update
from hil.inputs import ConfigError, InputError  # noqa: F401 (InputError: for the config's users)

BLOCK_S = 0.05  # s of samples handed to the estimator at once by default (estimator.batch_samples)
MIN_READ_S = 0.02  # the shortest time between a live trial's reads (Config.read_s)
MAX_READ_FRAMES = 50  # IMU frames a live read holds at most: 25 ms at 2 kHz (1.8 kB of KVH frames, under half a pty's buffer)
RATE_RATIO_TOLERANCE = 1e-9  # relative: how close imu.rate_hz / trial.rate_hz must be to an integer

class TrialConfig(Model):
    name: str = "trial"
    duration_s: float | None = Field(None, gt=0)  # required for emulated trials; data files set their own
    rate_hz: float = Field(200.0, gt=0, le=10000)
    seed: int = 0


class SiteConfig(Model):
    latitude_deg: float = Field(ge=-90, le=90)
    longitude_deg: float = Field(0.0, ge=-180, le=360)
    height_m: float = Field(0.0, ge=-1000, le=20000)
    # true gravity, emulator only (the estimator keeps normal gravity): deflection of the vertical
    # (xi north, eta east, positive when the plumb line's zenith lies north/east of the ellipsoid normal)
    deflection_arcsec: Vec2 = (0.0, 0.0)
    gravity_anomaly_mgal: float = Field(0.0, ge=-1000, le=1000)  # true minus normal gravity magnitude


class AxisMotion(Model):
    """One gimbal's commanded motion: swing ``amplitude*sin(2*pi*t/period + phase) + center``, or a rate."""

    amplitude_deg: float = 0.0
    period_s: float | None = Field(None, gt=0)
    phase_deg: float = 0.0
    center_deg: float = 0.0
    rate_dps: float = 0.0

    @model_validator(mode="after")
    def _period_for_amplitude(self) -> AxisMotion:
        if self.amplitude_deg != 0.0 and self.period_s is None:
            raise ValueError("period_s is required when amplitude_deg is not zero")
        return self


class Position(Model):
    """A dwell position of the ``positions`` motion."""

    outer_deg: float = 0.0
    middle_deg: float = 0.0
    inner_deg: float = 0.0
    dwell_s: float = Field(gt=0)


class Axes(Model):
    outer: AxisMotion = AxisMotion()
    middle: AxisMotion = AxisMotion()
    inner: AxisMotion = AxisMotion()


class MotionConfig(Model):
    kind: Literal["swing", "static", "positions", "rate"] = "swing"
    axes: Axes = Axes()
    positions: list[Position] = []
    rate_limit_dps: float = Field(20.0, gt=0)  # positions: move rate limit
    accel_limit_dps2: float = Field(20.0, gt=0)  # positions: move acceleration limit

    @model_validator(mode="after")
    def _positions_listed(self) -> MotionConfig:
        if self.kind == "positions" and not self.positions:
            raise ValueError("kind 'positions' needs a non-empty 'positions' list")
        return self


class LimitsConfig(Model):
    """Turntable limits per axis, ordered (outer, middle, inner)."""

    position_min_deg: Vec3 = (-180.0, -90.0, -180.0)
    position_max_deg: Vec3 = (180.0, 90.0, 180.0)
    rate_dps: Vec3 = (100.0, 100.0, 100.0)
    accel_dps2: Vec3 = (100.0, 100.0, 100.0)


class TurntableConfig(Model):
    source: Literal["emulator", "serial"] = "emulator"
    data_port: str | None = None
    command_port: str | None = None
    controller: Annotated[str, TABLE_CONTROLLERS.name_check()] = "acutrol"  # a table controller's registry name
    controller_options: Annotated[dict[str, Any], TABLE_CONTROLLERS.options_check("controller", fill=False)] = Field(
        default_factory=dict, validate_default=True)  # validated by the controller's own model
    data_protocol: Annotated[str, TABLE_CODECS.name_check()] = "tts1"  # a table data protocol's registry name
    baudrate: int = Field(115200, gt=0)
    motion: MotionConfig = MotionConfig()
    azimuth_deg: float = 0.0  # azimuth of the outer axis zero, from north towards east
    tilt_deg: Vec2 = (0.0, 0.0)  # small tilt of the table base about east (x) and north (y)
    mounting_deg: Vec3 = ZERO3  # IMU mounting on the inner gimbal, yaw/pitch/roll (z, x, y)
    latch_delay_us: float = Field(0.0, ge=0)  # emulator only: what its tts1 frames report
    limits: LimitsConfig = LimitsConfig()
    timing: DeviceTiming = DeviceTiming()
    faults: FaultConfig = FaultConfig()
    interlock_trip_at_s: float | None = Field(None, ge=0)  # emulator: an interlock opens at this time
    zero_offset_arcsec: Vec3 = ZERO3  # emulator truth: true gimbal angle minus encoder reading (outer, middle, inner)

    @model_validator(mode="after")
    def _serial_has_port(self) -> TurntableConfig:
        if self.source == "serial" and not self.data_port:
            raise ValueError("source 'serial' needs data_port (a pyserial URL)")
        return self


class ImuConfig(Model):
    source: Literal["emulator", "serial", "can"] = "emulator"
    protocol: Annotated[str, IMU_CODECS.name_check()] = "kvh1750"  # an IMU protocol's registry name
    # the device's own output settings, validated by its codec's model
    options: Annotated[dict[str, Any], IMU_CODECS.options_check("protocol")] = Field({}, validate_default=True)
    port: str | None = None
    baudrate: int = Field(921600, gt=0)
    can: CanConfig | None = None  # a CAN protocol: the default bus when left out
    rate_hz: float | None = Field(None, gt=0)  # defaults to trial.rate_hz
    latch_delay_us: float = Field(0.0, ge=0)  # from the pulse edge to the end of the increment interval
    timing: DeviceTiming = DeviceTiming()
    errors: ImuErrors = ImuErrors()
    faults: ImuFaultConfig = ImuFaultConfig()
    calibration: str | None = None  # a calibration.json: its inverse model applied to the raw increments

    @model_validator(mode="before")
    @classmethod
    def _old_keys_and_default_bus(cls, data: Any) -> Any:
        """The old ``imu.kvh1750`` block is taken as ``imu.options``, with a deprecation line; an emulated IMU
        on CAN without a ``can`` block is on the default bus (:class:`CanConfig`)."""
        if not isinstance(data, dict):
            return data
        data = dict(data)
        if "kvh1750" in data:
            if "options" in data:
                raise ValueError("kvh1750: give the KVH 1750's settings in imu.options only")
            import logging  # for this deprecation only

            logging.getLogger(__name__).warning("hil: imu.kvh1750 is deprecated and will be removed: write its keys "
                                                "under imu.options")
            data["options"] = data.pop("kvh1750")
        try:
            on_can = IMU_CODECS.get(data.get("protocol", "kvh1750")).link == "can"
        except (ValueError, TypeError):  # an unknown protocol: its field's check names it
            on_can = False
        return {**data, "can": {}} if on_can and data.get("can") is None and data.get("source", "emulator") == \
            "emulator" else data

    @model_validator(mode="after")
    def _transport_given(self) -> ImuConfig:
        if self.source == "serial" and not self.port:
            raise ValueError("source 'serial' needs port (a pyserial URL)")
        if self.source == "can" and self.can is None:
            raise ValueError("source 'can' needs a 'can' block (interface, channel, dbc)")
        return self


class EstimatorConfig(Model):
    solve_rate_hz: float = Field(1.0, gt=0)  # how often the solution is formed (display rate)
    rank_tolerance: float = Field(1e-6, gt=0, lt=1)  # relative eigenvalue floor of the scaled Gram matrix
    batch_samples: int | None = Field(None, ge=1, le=10000)  # live: samples a block spans (Config.block_samples)
    bias_model: Literal["constant", "drift"] = "constant"  # drift: b = b_s + k t (15 states)
    gyro_table_gate: bool = True  # off: no gyro sample is held to the table's rotation (hil ratetest's live form)
    pair_by_motion: bool = True  # off: the IMU is paired by its counter and receive times alone (frequency response)
    flags_end_trial: bool = True  # off: samples the IMU flags never end a trial early (hil ratetest: a step may clip)


class ReportLimits(Model):
    """Pass/fail limits of the trial report; a limit left out is not judged."""

    bias_sigma_ug_max: float | None = Field(None, gt=0)  # final 1-sigma of every bias axis
    bias_error_ug_max: float | None = Field(None, gt=0)  # |estimate - truth| per axis (emulated trials)
    converged_by_s: float | None = Field(None, gt=0)  # the bias must converge before this time
    method2_error_deg_max: float | None = Field(None, gt=0)  # |pitch|, |roll| of the method-2 alignment
    dropped_max: int | None = Field(None, ge=0)  # frames lost in the streams
    corrupt_max: int | None = Field(None, ge=0)  # corrupt frames in the streams
    calibration_residual_ug_max: float | None = Field(None, gt=0)  # |residual| at every calibration position
    calibration_error_sigma_max: float | None = Field(None, gt=0)  # |estimate - truth| / sigma, every term (emulated)
    missing_max: float | None = Field(0.001, ge=0, le=1)  # fractions of the IMU samples filled or bridged, ...
    gated_max: float | None = Field(0.001, ge=0, le=1)  # ... removed by the gyro/table gate, ...
    invalid_max: float | None = Field(0.001, ge=0, le=1)  # ... flagged invalid by the IMU itself, ...
    without_angles_max: float | None = Field(0.001, ge=0, le=1)  # ... aligned without table angles
    sync_offset_ms_max: float | None = Field(None, gt=0)  # |streams.sync_offset_ms|; default half an IMU period
    scale_factor_ppm_max: float | None = Field(None, gt=0)  # |scale factor error| per gyro (hil ratetest)
    nonlinearity_ppm_max: float | None = Field(None, gt=0)  # scale factor nonlinearity, of full-scale output
    asymmetry_ppm_max: float | None = Field(None, gt=0)  # |K+ - K-| / K per gyro


class CalibrationConfig(Model):
    """The multi-position calibration: dwell positions, rate plateaus and the terms to fit."""

    positions: Literal[18, 6] | list[Vec3] = 18  # the paper's 18 (or its 6 up/down) or (outer, middle, inner) deg
    dwell_s: float = Field(20.0, gt=0)
    settle_s: float = Field(2.0, ge=0)  # after each move or rate change, before the window starts
    plateau_rate_dps: float = Field(10.0, gt=0)  # gyro plateaus: both signs about each axis
    plateau_s: float = Field(36.0, ge=0)  # 0: no plateaus (accelerometers only)
    plateau_axes: list[Literal["outer", "middle", "inner"]] = Field(  # a rate table: its one axis
        default_factory=lambda: ["outer", "middle", "inner"], min_length=1)
    accel_terms: list[Literal["bias", "scale", "misalignment", "nonlinearity", "zero_offset"]] = [
        "bias", "scale", "misalignment", "nonlinearity", "zero_offset"]
    gyro_terms: list[Literal["bias", "scale", "misalignment", "zero_offset"]] = [
        "bias", "scale", "misalignment", "zero_offset"]
    rank_tolerance: float = Field(1e-6, gt=0, lt=1)  # a term's unexplained fraction of its scaled design column
    temperatures_c: list[float] | None = Field(None, min_length=1)  # chamber set points: a soak and the schedule at each
    soak: SoakSettings = SoakSettings()
    thermal_order: int = Field(1, ge=1, le=3)  # each term a polynomial of this order in the IMU's temperature

    @model_validator(mode="after")
    def _positions_listed(self) -> CalibrationConfig:
        if isinstance(self.positions, list) and not self.positions:
            raise ValueError("positions: expected 18, 6 or a non-empty list of [outer, middle, inner] deg")
        return self


class OutputConfig(Model):
    dir: str | None = None
    figures: bool = True
    outage_limit_s: float = Field(10.0, gt=0)  # live: no data from any device for this long ends the trial
    limits: ReportLimits = ReportLimits()
    stream_timeout_s: float = Field(5.0, gt=0)  # live: a stream's bytes without a frame this long end the trial


class RecordConfig(Model):
    """Who tested which unit where (all optional; ``--dut``, ``--operator``, ``--station`` override)."""

    dut_part: str | None = None
    dut_serial: str | None = None
    station: str | None = None
    operator: str | None = None
    notes: str | None = None


class UnitConfig(Model):
    """One IMU of several on the table (``units``, docs/units.md)."""

    name: str = Field(pattern=UNIT_NAME)
    record: RecordConfig = RecordConfig()
    mounting_deg: Vec3 = ZERO3  # as turntable.mounting_deg, this unit's
    imu: ImuConfig
    optional: bool = False  # a port that cannot be opened leaves the unit absent, not the trial refused


class Config(Model):
    trial: TrialConfig
    site: SiteConfig
    turntable: TurntableConfig = TurntableConfig()
    imu: ImuConfig = ImuConfig()
    estimator: EstimatorConfig = EstimatorConfig()
    calibration: CalibrationConfig = CalibrationConfig()
    scale_factor: ScaleFactorSettings = ScaleFactorSettings()
    frequency_response: FrequencyResponseSettings = FrequencyResponseSettings()
    output: OutputConfig = OutputConfig()
    record: RecordConfig = RecordConfig()
    environment: EnvironmentConfig = EnvironmentConfig()
    units: list[UnitConfig] | None = Field(None, min_length=1)  # several IMUs in place of imu (hil.config_units)

    @model_validator(mode="after")
    def _units_apart_and_imu_rates_divide_into_table_latches(self) -> Config:
        check_units(self.units, "imu" in self.model_fields_set)
        rates = {key: imu.rate_hz or self.trial.rate_hz for key, imu in self.imus.items()}
        first = next(iter(rates))
        for key, rate in rates.items():
            ratio = rate / self.trial.rate_hz
            if round(ratio) < 1 or abs(ratio - round(ratio)) > RATE_RATIO_TOLERANCE * ratio:
                raise ValueError(f"{key}.rate_hz: {rate:g} Hz is not an integer multiple of trial.rate_hz "
                                 f"({self.trial.rate_hz:g} Hz); both count one pulse train at the IMU rate and the "
                                 "table latches every n-th pulse")
            if rate != rates[first] and not self.turntable.timing.free_running:
                raise ValueError(f"{key}.rate_hz: {rate:g} Hz differs from {first}.rate_hz ({rates[first]:g} Hz): the "
                                 "table counts one sync pulse train, at one rate; units at different rates need a "
                                 "free-running table (turntable.timing.free_running: true)")
        return self

    @model_serializer(mode="wrap")
    def _units_without_imu(self, handler: Any) -> dict:
        """A units config written out without the one-unit ``imu`` block it never had, so that it reads back."""
        data = handler(self)
        if self.units:
            data.pop("imu", None)
        return data

    def unit_configs(self) -> dict[str, Config]:
        """Each unit's one-unit config by its name (:func:`hil.config_units.unit_update`); empty with ``imu``."""
        data = self.model_dump()
        return {unit.name: Config.model_validate(unit_update(data, unit)) for unit in self.units or ()}

    @model_validator(mode="after")
    def _temperatures_within_the_chamber(self) -> Config:
        """``calibration.temperatures_c`` against the chamber (:func:`hil.config_environment.check_temperatures`)."""
        check_temperatures(self.calibration.temperatures_c, self.calibration.thermal_order, self.environment.chamber)
        return self

    @property
    def imus(self) -> dict[str, ImuConfig]:
        """Each IMU by its key: ``imu``, or ``units[k].imu`` of each unit."""
        return {f"units[{k}].imu": unit.imu for k, unit in enumerate(self.units or ())} or {"imu": self.imu}

    @property
    def imu_rate_hz(self) -> float:
        """The rate of the sync pulse train (and of the IMU's samples)."""
        return self.imu.rate_hz or self.trial.rate_hz

    def emulated_only(self, source: str, command: str) -> None:
        """Raise :class:`ConfigError` when a device is read from a port (``command`` would simulate it)."""
        sources = {f"{key}.source": imu.source for key, imu in self.imus.items()}
        for key, value in (*sources.items(), ("turntable.source", self.turntable.source)):
            if value != "emulator":
                raise ConfigError(f"{source}: {key}: {value}: {command} emulates the devices; a config that reads "
                                  f"devices runs with hil run, hil calibrate or hil noise")

    @property
    def limits(self) -> ReportLimits:
        """``output.limits`` as judged: ``sync_offset_ms_max`` defaults to half an IMU period."""
        limits = self.output.limits
        default = {"sync_offset_ms_max": 500.0 / self.imu_rate_hz} if limits.sync_offset_ms_max is None else {}
        return limits.model_copy(update=default)

    @property
    def block_samples(self) -> int:
        """Samples the estimator takes at once: ``estimator.batch_samples``, else those of :data:`BLOCK_S` (an update
        costs about the same whatever its size: an IMU at 2 kHz is then as cheap to estimate as one at 200 Hz)."""
        return self.estimator.batch_samples or max(1, round(BLOCK_S * self.imu_rate_hz))

    @property
    def reads_per_block(self) -> int:
        """Live reads a block is split into: at most :data:`MAX_READ_FRAMES` IMU frames a read."""
        return math.ceil(self.block_samples / MAX_READ_FRAMES)

    @property
    def read_s(self) -> float:
        """s between a live trial's reads: one block, or the largest whole fraction of it that holds at most
        :data:`MAX_READ_FRAMES` IMU frames, at least :data:`MIN_READ_S` (docs/harness.md, "What a read costs, and
        the block length")."""
        return max(self.block_samples / self.imu_rate_hz / self.reads_per_block, MIN_READ_S)

    @property
    def table_divider(self) -> int:
        """n: the table latches every n-th pulse of the train, ``imu_rate_hz / trial.rate_hz``."""
        return round(self.imu_rate_hz / self.trial.rate_hz)

    @property
    def table_counts_per_frame(self) -> int:
        """Steps of the ``tts1`` sync counter between consecutive table frames: n when the table counts the
        pulse train, 1 when it is free-running (it counts its own latches)."""
        return 1 if self.turntable.timing.free_running else self.table_divider

    @property
    def table_counter_rate_hz(self) -> float:
        """Counts per second of the ``tts1`` sync counter: the pulse train's rate, or the table's own latch
        rate when it is free-running."""
        return self.trial.rate_hz if self.turntable.timing.free_running else self.imu_rate_hz


def parse_config(data: Any, source: str = "config", units: bool = False) -> Config:
    """Validate a mapping (already parsed YAML) into a :class:`Config`; one with ``units`` only for a caller that
    takes several units (``units``)."""
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: expected a mapping at the top level, got {type(data).__name__}")
    try:
        cfg = Config.model_validate(data)
    except ValidationError as exc:
        raise ConfigError(f"{source}: {describe_validation(exc)}") from None
    return cfg if units else one_unit_only(cfg, source)


def load_config(path: str | Path, units: bool = False) -> Config:
    """Read and validate a YAML trial configuration (safe loader only); ``units`` as :func:`parse_config`'s."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read: {exc.strerror or exc}") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"{path}:{mark.line + 1}:{mark.column + 1}" if mark is not None else str(path)
        raise ConfigError(f"{where}: not valid YAML: {getattr(exc, 'problem', None) or exc}") from None
    return parse_config(data, str(path), units)
