"""The records that flow between devices, drivers, the aligner and the estimators.

Decoded samples travel as struct-of-arrays batches, one per read, on the live path and in replay
(single records remain for the emulators and the codecs' one-frame API); the aligner releases runs
of aligned samples as batches, and a simulation or a CSV import feeds aligned batches directly. All quantities are SI: rad, m/s, s. Gimbal angles are always ordered
(outer, middle, inner).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

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
    status: int | None = None  # the device's status word; None: a healthy device's (its codec's ``healthy_status``)
    temperature_c: float = math.nan  # deg C, the device's own temperature when its frames carry one


@dataclass(frozen=True, slots=True)
class TableSample:
    """One turntable output: gimbal angles latched at a sync pulse (plus the latch delay)."""

    sync_index: int
    angles: tuple[float, float, float]  # rad, (outer, middle, inner)
    host_time: float = float("nan")
    device_time: float | None = None
    latch_delay: float = 0.0  # s, from the pulse edge to the encoder latch
    status: int = 0


@dataclass(frozen=True)
class ImuSamples:
    """Struct-of-arrays form of decoded IMU samples (the frames of one read): sync indices (N,) int64,
    increments (N, 3), host receive times (N,), status words (N,), the device's temperature (N,) deg C (NaN where
    its frames carry none) and whether the device marks each sample valid (N,) bool (its health flags, judged
    by the pipeline; all valid until then)."""

    sync_index: np.ndarray
    dtheta: np.ndarray
    dv: np.ndarray
    host_time: np.ndarray
    status: np.ndarray
    temperature_c: np.ndarray | None = None  # None: NaN for every sample
    valid: np.ndarray | None = None  # None: every sample valid

    def __post_init__(self) -> None:
        n = len(self.sync_index)
        if self.temperature_c is None:
            object.__setattr__(self, "temperature_c", np.full(n, np.nan))
        if self.valid is None:
            object.__setattr__(self, "valid", np.ones(n, dtype=bool))

    def __len__(self) -> int:
        return len(self.sync_index)

    def take(self, mask: np.ndarray) -> ImuSamples:
        """The samples where ``mask`` (or an index array) selects."""
        return ImuSamples(self.sync_index[mask], self.dtheta[mask], self.dv[mask], self.host_time[mask],
                          self.status[mask], self.temperature_c[mask], self.valid[mask])

    def records(self) -> list[ImuSample]:
        """One record a sample."""
        return [ImuSample(k, tuple(a), tuple(b), t, None, status, temperature) for k, a, b, t, status, temperature
                in zip(self.sync_index.tolist(), self.dtheta.tolist(), self.dv.tolist(), self.host_time.tolist(),
                       self.status.tolist(), self.temperature_c.tolist(), strict=True)]

    @classmethod
    def stack(cls, samples: list[ImuSample]) -> ImuSamples:
        return cls(np.array([s.sync_index for s in samples], dtype=np.int64),
                   np.array([s.dtheta for s in samples], dtype=float).reshape(-1, 3),
                   np.array([s.dv for s in samples], dtype=float).reshape(-1, 3),
                   np.array([s.host_time for s in samples], dtype=float),
                   np.array([s.status or 0 for s in samples], dtype=np.int64),
                   np.array([s.temperature_c for s in samples], dtype=float))


@dataclass(frozen=True)
class TableSamples:
    """Struct-of-arrays form of decoded table samples: sync indices (N,) int64, angles (N, 3) rad, host
    receive times (N,), latch delays (N,) s, status bytes (N,)."""

    sync_index: np.ndarray
    angles: np.ndarray
    host_time: np.ndarray
    latch_delay: np.ndarray
    status: np.ndarray

    def __len__(self) -> int:
        return len(self.sync_index)

    def records(self) -> list[TableSample]:
        """One record a sample."""
        return [TableSample(k, tuple(a), t, None, d, status) for k, a, t, d, status in zip(
            self.sync_index.tolist(), self.angles.tolist(), self.host_time.tolist(), self.latch_delay.tolist(),
            self.status.tolist(), strict=True)]

    @classmethod
    def stack(cls, samples: list[TableSample]) -> TableSamples:
        return cls(np.array([s.sync_index for s in samples], dtype=np.int64),
                   np.array([s.angles for s in samples], dtype=float).reshape(-1, 3),
                   np.array([s.host_time for s in samples], dtype=float),
                   np.array([s.latch_delay for s in samples], dtype=float),
                   np.array([s.status for s in samples], dtype=np.int64))


@dataclass(frozen=True, slots=True)
class AlignedSample:
    """What the estimator consumes: increments over (t - dt, t] and, when known, the table angles at t."""

    t: float
    dtheta: tuple[float, float, float]
    dv: tuple[float, float, float]
    angles: tuple[float, float, float] | None = None


NO_ANGLES = (math.nan, math.nan, math.nan)  # a sample or a gap's end without table angles


@dataclass(frozen=True, slots=True)
class ImuGap:
    """IMU samples lost over (t_start, t_end]: the estimator carries its attitude across with the table
    angles at both ends (``NO_ANGLES`` where the table had none) and takes no measurement from the gap."""

    t_start: float
    t_end: float
    angles_start: tuple[float, float, float]
    angles_end: tuple[float, float, float]

    @property
    def known(self) -> bool:
        """The table's angles are known at both ends."""
        return not any(math.isnan(a) for a in (*self.angles_start, *self.angles_end))


@dataclass(frozen=True)
class AlignedBatch:
    """Struct-of-arrays form of consecutive aligned samples (the aligner's runs, simulation, CSV import).

    ``t`` (N,) ends each increment interval; ``dtheta`` and ``dv`` are (N, 3); ``angles`` is (N, 3)
    (outer, middle, inner) at ``t``, NaN rows for the samples without angles, or None from a source that has
    no turntable reference at all (a simulation or a CSV without angles: the pipeline takes it as NaN rows,
    :meth:`angle_rows`). ``valid`` (N,) bool marks the samples the device flagged invalid (False), which the
    estimator never takes; None: every sample valid. ``temperature_c`` (N,): a simulated IMU's temperature.
    """

    t: np.ndarray
    dtheta: np.ndarray
    dv: np.ndarray
    angles: np.ndarray | None = None
    t0: float = field(default=0.0)  # start of the first interval
    valid: np.ndarray | None = None
    temperature_c: np.ndarray | None = None  # (N,) the IMU's temperature (deg C) where the source has one

    def __post_init__(self) -> None:
        n = len(self.t)
        for name in ("dtheta", "dv"):
            if getattr(self, name).shape != (n, 3):
                raise ValueError(f"{name} must have shape ({n}, 3), got {getattr(self, name).shape}")
        if self.angles is not None and self.angles.shape != (n, 3):
            raise ValueError(f"angles must have shape ({n}, 3), got {self.angles.shape}")

    def __len__(self) -> int:
        return len(self.t)

    @property
    def has_angles(self) -> bool:
        """Every sample has its table angles."""
        return self.angles is not None and not np.isnan(self.angles).any()

    def angle_rows(self) -> np.ndarray:
        """The angles (N, 3), NaN rows where a sample has none."""
        return self.angles if self.angles is not None else np.full((len(self.t), 3), np.nan)

    @classmethod
    def from_samples(cls, samples: list[AlignedSample], t0: float) -> AlignedBatch:
        """Stack single samples into a batch; angles are kept only if every sample has them."""
        t = np.array([s.t for s in samples], dtype=float)
        dtheta = np.array([s.dtheta for s in samples], dtype=float).reshape(-1, 3)
        dv = np.array([s.dv for s in samples], dtype=float).reshape(-1, 3)
        has_angles = bool(samples) and all(s.angles is not None for s in samples)
        angles = np.array([s.angles for s in samples], dtype=float) if has_angles else None
        return cls(t, dtheta, dv, angles, t0)


@dataclass(frozen=True)
class StreamCounts:
    """A trial's stream counters: result.json's ``streams`` (``extra``: the detailed counts, in order; read-only
    where the pipeline publishes them)."""

    imu_frames: int = 0
    table_frames: int = 0
    aligned: int = 0
    dropped: int = 0
    corrupt: int = 0
    extra: Mapping[str, int | float | dict | None] = field(default_factory=lambda: MappingProxyType({}))

    def as_dict(self) -> dict[str, int | float | None]:
        return {
            "imu_frames": self.imu_frames,
            "table_frames": self.table_frames,
            "aligned": self.aligned,
            "dropped": self.dropped,
            "corrupt": self.corrupt,
            **self.extra,
        }
