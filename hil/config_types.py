"""The building blocks of the trial configuration's models (:mod:`hil.config`): fixed-length vectors of finite
numbers, and the base model (unknown keys are errors, instances are frozen)."""

from __future__ import annotations

import math
from typing import Annotated, Any

from pydantic import BaseModel, BeforeValidator, ConfigDict, ValidationError


def _vector(n: int):
    def check(value: Any) -> Any:
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            raise ValueError(f"expected {n} numbers, got a single number")
        if not isinstance(value, (list, tuple)):
            raise ValueError(f"expected a list of {n} numbers, got {type(value).__name__}")
        if len(value) != n:
            raise ValueError(f"expected {n} numbers, got {len(value)}")
        for v in value:
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f"expected {n} finite numbers, got {v!r}")
        return tuple(float(v) for v in value)

    return BeforeValidator(check)


Vec3 = Annotated[tuple[float, float, float], _vector(3)]
Vec2 = Annotated[tuple[float, float], _vector(2)]
Vec6 = Annotated[tuple[float, float, float, float, float, float], _vector(6)]
ZERO3 = (0.0, 0.0, 0.0)


class Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, ser_json_inf_nan="constants")  # an inf survives JSON


def describe_validation(error: ValidationError) -> str:
    lines = []
    for item in error.errors():
        path = "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in item["loc"]).lstrip(".")
        msg = {"extra_forbidden": "unknown key", "missing": "required key is missing"}.get(
            item["type"], item["msg"].removeprefix("Value error, "))
        lines.append(f"{path}: {msg}" if path else msg)
    return "; ".join(lines)
