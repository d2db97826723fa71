"""Sampling the simulated truth through the sensors into a measurement log."""

from __future__ import annotations

import numpy as np

from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.log import MeasurementLog
from spaceid_gym.sim.sensors import Measurement, Sampler, SensorModel
from spaceid_gym.sim.state import FreeFloatingState


class LogRecorder:
    """Measures states with a sensor model and keeps the samples of one window.

    Args:
        sensors: noise model.
        sample_period_s: the sample period (sets the per-sample noise of rate sensors).
        rng: the seeded generator all noise is drawn from.
    """

    def __init__(self, sensors: SensorModel, sample_period_s: float, rng: np.random.Generator) -> None:
        self.sensors = sensors
        self.sample_period_s = sample_period_s
        self.rng = rng
        self._sample: Sampler | None = None
        self._t: list[float] = []
        self._samples: list[Measurement] = []

    def record(self, state: FreeFloatingState, gyro_state: FreeFloatingState | None = None) -> Measurement:
        """Measure ``state``, keep the sample and return it.

        ``gyro_state``: the state the gyro sees instead of ``state`` (a gyro lagging the encoders);
        the sample keeps ``state``'s time.
        """
        if self._sample is None:
            self._sample = self.sensors.sampler(state.q_rad.shape[0], self.sample_period_s)
        sample = self._sample(state, self.rng, gyro_state)
        self._t.append(state.t_s)
        self._samples.append(sample)
        return sample

    def __len__(self) -> int:
        return len(self._t)

    def log(self, last: int | None = None) -> MeasurementLog:
        """The samples so far as a :class:`~spaceid_gym.log.MeasurementLog` (without attitude if the sensors measure none).

        ``last``: only the last ``last`` samples (all when ``None`` or more than recorded).
        """
        if last is not None and (isinstance(last, bool) or not isinstance(last, int) or last < 1):
            raise SpaceIdInputError(f"last: expected a positive number of samples or None, got {last!r}")
        start = 0 if last is None else max(len(self._t) - last, 0)
        samples = self._samples[start:]
        quats = [m.quat_base_to_inertial_wxyz for m in samples]
        return MeasurementLog(
            t_s=np.array(self._t[start:]),
            q_rad=np.array([m.q_rad for m in samples]),
            dq_rad_s=np.array([m.dq_rad_s for m in samples]),
            omega_base_body_rad_s=np.array([m.omega_base_body_rad_s for m in samples]),
            quat_base_to_inertial_wxyz=None if any(q is None for q in quats) else np.array(quats),  # None: no attitude source
        ).validate("simulated log")
