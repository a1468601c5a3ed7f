"""The emulated devices' side of the trial configuration: how each latches and keeps time, the faults injected
into its output, and the IMU's sensor errors (``imu.errors``). Read by the emulator, and by the outputs as the
truth of an emulated trial; the harness reading real devices ignores them."""

from __future__ import annotations

from pydantic import Field

from hil.config_types import ZERO3, Model, Vec3, Vec6


class DeviceTiming(Model):
    """How a device latches on the sync pulse and keeps its own time (emulated devices)."""

    latch_jitter_us: float = Field(0.0, ge=0)  # 1-sigma jitter of the latch instant about pulse + delay
    clock_drift_ppm: float = 0.0  # rate error of the device's own clock (its timestamps)
    free_running: bool = False  # no sync input: the device latches on its own (drifting) clock
    counter_start: int | None = Field(None, ge=0)  # counter at trial time 0; None: from trial.seed (emulators.clocks)


class FaultConfig(Model):
    """Faults injected into one emulated device's output; all off by default. Rates are per frame."""

    drop_rate: float = Field(0.0, ge=0, le=1)  # probability that a drop burst starts at a frame
    drop_burst: int = Field(1, ge=1)  # frames lost per drop event
    corrupt_byte_rate: float = Field(0.0, ge=0, le=1)  # probability per byte of a flipped bit
    truncate_rate: float = Field(0.0, ge=0, le=1)  # frames cut short
    duplicate_rate: float = Field(0.0, ge=0, le=1)  # frames sent twice
    reorder_rate: float = Field(0.0, ge=0, le=1)  # frames swapped with the next one
    jitter_ms: float = Field(0.0, ge=0)  # extra write latency, uniform in [0, jitter_ms]
    unplug_at_s: float | None = Field(None, ge=0)  # trial time of an unplug (pty closed / CAN silent)
    unplug_s: float = Field(0.0, ge=0)  # how long the device stays unplugged
    power_cycle_at_s: float | None = Field(None, ge=0)  # trial time the device loses power (port stays open)
    power_cycle_s: float = Field(0.0, ge=0)  # how long it is silent; then its counter restarts from 0


class ImuFaultConfig(FaultConfig):
    """An emulated IMU's faults: the frame faults of every device, and the samples it flags invalid in its own
    status word (the flags its codec raises at start-up, :attr:`drivers.codec.Codec.start_up_flags`)."""

    invalid_rate: float = Field(0.0, ge=0, le=1)  # probability that a sample is flagged invalid
    invalid_at_s: float | None = Field(None, ge=0)  # trial time from which every sample is flagged ...
    invalid_s: float = Field(0.0, ge=0)  # ... for this long
    start_up_s: float = Field(0.0, ge=0)  # after power-on (the trial's start, a power cycle's end) flagged this long


class ThermalErrors(Model):
    """``imu.errors.thermal``: the sensor's temperature after the chamber's and power-on, and its bias and scale
    factor errors as polynomials in T - reference_c (emulators/thermal.py)."""

    reference_c: float = Field(25.0, ge=-60, le=125)
    accel_bias_ug_per_c: Vec3 = ZERO3
    accel_bias_ug_per_c2: Vec3 = ZERO3
    gyro_bias_dph_per_c: Vec3 = ZERO3
    accel_scale_ppm_per_c: Vec3 = ZERO3
    gyro_scale_ppm_per_c: Vec3 = ZERO3
    case_tau_s: float = Field(600.0, gt=0)  # the case follows the chamber's air with this time constant
    self_heating_c: float = Field(0.0, ge=-20, le=50)  # the electronics' rise above the case after power-on ...
    warmup_tau_s: float = Field(300.0, gt=0)  # ... with this time constant


class ImuErrors(Model):
    """Sensor errors applied by the emulator; per-axis lists (x, y, z). All off by default."""

    accel_bias_ug: Vec3 = ZERO3
    turn_on_bias_ug: Vec3 = ZERO3  # 1-sigma spread of the accel bias between power-ons (hil plan's emulated supply)
    accel_noise_ug: Vec3 = ZERO3  # white, 1-sigma per sample
    accel_drift_ug_per_h: Vec3 = ZERO3  # linear bias drift b = b_s + k t
    accel_random_walk_ug_per_sqrt_h: Vec3 = ZERO3  # bias random walk
    accel_bias_instability_ug: Vec3 = ZERO3  # flicker bias B (IEEE 952): Allan deviation floor 0.664 B
    accel_scale_ppm: Vec3 = ZERO3
    accel_misalignment_arcsec: Vec6 = (0.0,) * 6  # (xy, xz, yx, yz, zx, zy)
    accel_nonlinearity_ug_per_g2: Vec3 = ZERO3  # quadratic scale factor term K_nl
    gyro_bias_dph: Vec3 = ZERO3
    gyro_noise_dph: Vec3 = ZERO3  # white, 1-sigma per sample
    gyro_drift_dph_per_h: Vec3 = ZERO3
    gyro_random_walk_dph_per_sqrt_h: Vec3 = ZERO3
    gyro_bias_instability_dph: Vec3 = ZERO3
    gyro_scale_ppm: Vec3 = ZERO3
    gyro_misalignment_arcsec: Vec6 = (0.0,) * 6
    scale_asymmetry_ppm: Vec3 = ZERO3  # gyro scale factor K+ - K- (of K) between positive and negative rates
    bandwidth_hz: float | None = Field(None, gt=0)  # gyros' second-order low-pass, -3 dB; None: none
    damping: float = Field(0.7, gt=0, le=2)  # the low-pass's damping ratio
    delay_ms: float = Field(0.0, ge=0, le=1000)  # pure delay of the IMU's output
    gyro_range_dps: float | None = Field(None, gt=0)  # the gyros' output clips at +- this; None: no range
    dtheta_quantum_rad: float = Field(0.0, ge=0)  # output quantisation of the angle increment
    dv_quantum_mps: float = Field(0.0, ge=0)  # output quantisation of the velocity increment
    temperature_c: float = Field(25.0, ge=-60, le=125)  # the sensor's temperature the IMU reports in its frames
    thermal: ThermalErrors | None = None  # temperature_c is then the sensor's at power-on, and it follows the chamber
