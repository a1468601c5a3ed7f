"""The records that flow between devices, drivers, the aligner and the estimators.

Single samples travel as small frozen records on the live path; simulation and replay use the
struct-of-arrays batches. All quantities are SI: rad, m/s, s. Gimbal angles are always ordered
(outer, middle, inner).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

GIMBAL_AXES = ("outer", "middle", "inner")


@dataclass(frozen=True, slots=True)
class ImuSample:
    """One IMU output: increments over the interval that ends at the latching sync pulse."""

    sync_index: int
    dtheta: tuple[float, float, float]  # rad
    dv: tuple[float, float, float]  # m/s
    host_time: float = float("nan")  # s, host clock at reception
    device_time: float | None = None  # s, the device's own clock when it reports one
    status: int = 0


@dataclass(frozen=True, slots=True)
class TableSample:
    """One turntable output: gimbal angles latched at a sync pulse (plus the latch delay)."""

    sync_index: int
    angles: tuple[float, float, float]  # rad, (outer, middle, inner)
    host_time: float = float("nan")
    device_time: float | None = None
    latch_delay: float = 0.0  # s, from the pulse edge to the encoder latch
    status: int = 0


@dataclass(frozen=True, slots=True)
class AlignedSample:
    """What the estimator consumes: increments over (t - dt, t] and, when known, the table angles at t."""

    t: float
    dtheta: tuple[float, float, float]
    dv: tuple[float, float, float]
    angles: tuple[float, float, float] | None = None


@dataclass(frozen=True, slots=True)
class ImuGap:
    """IMU samples lost over (t_start, t_end]: the estimator carries its attitude across with the table
    angles at both ends (None where the table had none) and takes no measurement from the gap."""

    t_start: float
    t_end: float
    angles_start: tuple[float, float, float] | None
    angles_end: tuple[float, float, float] | None


@dataclass(frozen=True)
class AlignedBatch:
    """Struct-of-arrays form of consecutive aligned samples (simulation, replay, CSV import).

    ``t`` (N,) ends each increment interval; ``dtheta`` and ``dv`` are (N, 3); ``angles`` is (N, 3)
    (outer, middle, inner) at ``t`` or None when no turntable reference exists.
    """

    t: np.ndarray
    dtheta: np.ndarray
    dv: np.ndarray
    angles: np.ndarray | None = None
    t0: float = field(default=0.0)  # start of the first interval

    def __post_init__(self) -> None:
        n = len(self.t)
        for name in ("dtheta", "dv"):
            if getattr(self, name).shape != (n, 3):
                raise ValueError(f"{name} must have shape ({n}, 3), got {getattr(self, name).shape}")
        if self.angles is not None and self.angles.shape != (n, 3):
            raise ValueError(f"angles must have shape ({n}, 3), got {self.angles.shape}")

    def __len__(self) -> int:
        return len(self.t)

    @classmethod
    def from_samples(cls, samples: list[AlignedSample], t0: float) -> AlignedBatch:
        """Stack single samples into a batch; angles are kept only if every sample has them."""
        t = np.array([s.t for s in samples], dtype=float)
        dtheta = np.array([s.dtheta for s in samples], dtype=float).reshape(-1, 3)
        dv = np.array([s.dv for s in samples], dtype=float).reshape(-1, 3)
        has_angles = bool(samples) and all(s.angles is not None for s in samples)
        angles = np.array([s.angles for s in samples], dtype=float) if has_angles else None
        return cls(t, dtheta, dv, angles, t0)


@dataclass
class StreamCounts:
    """A trial's stream counters: result.json's ``streams`` (``extra``: the detailed counts, in order)."""

    imu_frames: int = 0
    table_frames: int = 0
    aligned: int = 0
    dropped: int = 0
    corrupt: int = 0
    extra: dict[str, int | float | None] = field(default_factory=dict)

    def as_dict(self) -> dict[str, int | float | None]:
        return {
            "imu_frames": self.imu_frames,
            "table_frames": self.table_frames,
            "aligned": self.aligned,
            "dropped": self.dropped,
            "corrupt": self.corrupt,
            **self.extra,
        }
