"""The device's own word on its samples: the health flags its codec declares (:class:`~drivers.codec.HealthFlag`),
read from each sample's status word. A sample a flag marks invalid is never estimated: it is counted here (in
all and by flag, result.json's ``streams.imu_invalid`` and ``streams.imu_invalid_by_flag``) and goes on marked,
so that the gate turns it into a gap the estimator bridges with the table (docs/devices.md, "Health flags")."""

from __future__ import annotations

import dataclasses

import numpy as np

from drivers.codec import HealthFlag, raised_flags
from hil.samples import ImuSamples

FLAG_PREFIX = "flag_"  # a flag's count of samples among the stream health figures: ``flag_<name>`` (/health/flags)


class HealthCheck:
    """Marks the samples the device flags invalid by ``flags``; :attr:`invalid` counts them, :attr:`by_flag` per
    flag (a sample may raise several), :attr:`last_raised` names the flags of the last invalid sample."""

    def __init__(self, flags: tuple[HealthFlag, ...]) -> None:
        self.flags = flags
        self.invalid = 0
        self.by_flag = {flag.name: 0 for flag in flags}
        self.last_raised: tuple[str, ...] = ()

    def marked(self, samples: ImuSamples) -> ImuSamples:
        """The samples with ``valid`` False where a flag is raised (counted)."""
        if not self.flags or not len(samples):
            return samples
        raised = raised_flags(self.flags, samples.status)
        bad = raised.any(axis=1)
        if not bad.any():
            return samples
        self.invalid += int(bad.sum())
        for flag, n in zip(self.flags, raised.sum(axis=0).tolist(), strict=True):
            self.by_flag[flag.name] += n
        last = raised[np.flatnonzero(bad)[-1]]
        self.last_raised = tuple(flag.name for flag, hit in zip(self.flags, last, strict=True) if hit)
        return dataclasses.replace(samples, valid=samples.valid & ~bad)

    def diagnosis(self, keys: object = None) -> str:
        """What the device says when it flags every sample (``keys``: unused, the checks' common signature)."""
        return (f"the IMU flags every sample invalid ({', '.join(self.last_raised)} in its status word): "
                "a failed built-in test, or a sensor out of its range?")

    def counts(self) -> dict[str, int | dict[str, int]]:
        """result.json's ``imu_invalid`` and ``imu_invalid_by_flag`` (the flags raised at least once)."""
        return {"imu_invalid": self.invalid,
                "imu_invalid_by_flag": {name: n for name, n in self.by_flag.items() if n}}
