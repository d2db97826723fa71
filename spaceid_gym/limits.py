"""Limits on the sizes a user asks for, checked before anything runs, against what this machine can hold.

A size that cannot finish (``spaceid simulate --duration 1e12`` is 5e13 samples at 50 Hz) must be refused at once,
naming the option and the largest value that fits, instead of filling the memory or running for years.

* **A log** (:func:`check_log_size`): its samples are held in memory several times over (the recorder's rows, the
  log's arrays, the identification model's predictions for a few parameter vectors at once), about
  :data:`BYTES_PER_SAMPLE_VALUE` bytes per value and :data:`COPIES_PER_LOG` copies; a log may use at most
  :data:`MEMORY_FRACTION` of the machine's physical memory, and at most :data:`MAX_LOG_SAMPLES` samples (at the
  simulator's ~2e4 steps per second, a day of simulation).
* **A count** (:func:`check_count`): settings, seeds, logs, jobs: an integer in ``[1, maximum]``.
"""

from __future__ import annotations

import math
import os

from spaceid_gym.errors import SpaceIdInputError

#: the most samples one log may have: 1e8 would be 23 days at 50 Hz and hours of simulation per million
MAX_LOG_SAMPLES = 20_000_000

#: bytes per stored value (float64)
BYTES_PER_SAMPLE_VALUE = 8

#: copies of a log's values held at once while simulating and identifying it (recorder, log, model's predictions)
COPIES_PER_LOG = 40

#: the share of physical memory one log may take
MEMORY_FRACTION = 0.25

#: the most settings, seeds or logs one command may run
MAX_RUNS = 1_000_000

#: the most worker processes per core
MAX_JOBS_PER_CORE = 8


def physical_memory_bytes() -> int:
    """The machine's physical memory, bytes (``os.sysconf``); 8 GiB where the system does not say."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return 8 * 2**30


def max_log_samples(n_joints: int) -> int:
    """The most samples a log of a robot with ``n_joints`` joints may have on this machine (see the module docstring)."""
    values_per_sample = 2 * n_joints + 8  # time, joint angles and rates, gyro, quaternion
    by_memory = MEMORY_FRACTION * physical_memory_bytes() / (values_per_sample * BYTES_PER_SAMPLE_VALUE * COPIES_PER_LOG)
    return int(min(MAX_LOG_SAMPLES, by_memory))


def check_log_size(duration_s: float, sample_period_s: float, n_joints: int, option: str = "duration") -> int:
    """The number of samples of a log of ``duration_s`` at ``sample_period_s``; raises naming ``option`` when the
    duration or period is not a positive finite number or the log would not fit (:func:`max_log_samples`).

    Raises:
        SpaceIdInputError: naming ``option``, the samples asked for and the longest duration that fits.
    """
    if not (math.isfinite(duration_s) and duration_s > 0.0):
        raise SpaceIdInputError(f"{option}: expected a positive number of seconds, got {duration_s!r}")
    if not (math.isfinite(sample_period_s) and sample_period_s > 0.0):
        raise SpaceIdInputError(f"sample period: expected a positive number of seconds, got {sample_period_s!r}")
    samples = duration_s / sample_period_s
    limit = max_log_samples(n_joints)
    if samples > limit:
        raise SpaceIdInputError(
            f"{option}: {duration_s:g} s at {1.0 / sample_period_s:g} Hz is {samples:.3g} samples; this machine holds "
            f"at most {limit:.3g} per log (at most {limit * sample_period_s:.4g} s at this rate)"
        )
    return round(samples)


def check_count(value: int, option: str, maximum: int = MAX_RUNS) -> int:
    """``value`` if it is an integer in ``[1, maximum]``.

    Raises:
        SpaceIdInputError: naming ``option`` and the range.
    """
    if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= maximum:
        raise SpaceIdInputError(f"{option}: expected an integer from 1 to {maximum}, got {value!r}")
    return value


def max_jobs() -> int:
    """The most worker processes a command may start: :data:`MAX_JOBS_PER_CORE` per core."""
    return MAX_JOBS_PER_CORE * (os.cpu_count() or 1)
