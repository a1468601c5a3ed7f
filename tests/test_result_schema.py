"""result.json's schema (hil/outputs/result_schema.py, docs/contracts.md "result.json"): the committed
docs/result.schema.json is the model's export, and the model rejects a document the contract does not allow.
The trials' own result.json files are validated where those trials run (tests/test_record_outputs.py,
tests/test_history.py)."""

from __future__ import annotations

import json

import pytest
from pydantic import ValidationError

from hil.outputs.result_schema import SCHEMA_FILE, Result, schema_text

MINIMAL = {"trial": {"name": "t", "duration_s": 1.0, "samples": 100}, "ended": "completed",
           "calibration_applied": None, "streams": {"imu_frames": 100}, "estimate": None, "table_reference": None,
           "alignment_deg": None}


def test_the_committed_json_schema_is_the_models_export():
    assert SCHEMA_FILE.read_text() == schema_text(), "run: python -m hil.outputs.result_schema"
    assert json.loads(SCHEMA_FILE.read_text())["title"] == "Result"


def test_a_minimal_result_is_valid_and_a_misspelt_or_mistyped_key_is_not():
    Result.model_validate(MINIMAL)
    with pytest.raises(ValidationError, match="trail"):
        Result.model_validate({**MINIMAL, "trail": {}})
    with pytest.raises(ValidationError, match="samples"):
        Result.model_validate({**MINIMAL, "trial": {"name": "t", "duration_s": 1.0, "samples": "many"}})
    with pytest.raises(ValidationError, match="ended"):
        Result.model_validate({k: v for k, v in MINIMAL.items() if k != "ended"})
