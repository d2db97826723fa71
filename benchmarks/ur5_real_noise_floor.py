"""An estimate of the real UR5 currents' noise floor, in the unit of the held-out error: per joint, % of the movement's
processed current, so the leave-one-out figures can be read against it.

The identification keeps the current below the low-pass cutoff (:class:`~estimators.arm.identification.Preparation`,
4 Hz); the model cannot follow what is above it, and the joints' motion lies below 2 Hz. Per movement and joint:

* ``sigma_raw_A``: the std of the raw current minus its zero-phase low-pass (the part above the cutoff), divided by
  ``sqrt(1 - g^2)`` with ``g`` = :meth:`~estimators.arm.identification.Preparation.noise_gain` (white noise of std
  ``sigma`` keeps ``sigma^2 (1 - g^2)`` above the cutoff);
* ``floor``: ``sigma_raw_A * g``, what that white noise leaves in the processed current;
* ``floor %``: ``100 floor / RMS(processed current)``, the relative error (``100 ||e|| / ||i||``) a model exact up
  to white noise would reach; overall: the same over all joints at once.

The assumption is white noise across the band. The content above the cutoff grows with the movement's
accelerations (largest on ``Movement_No3_Acc``), so part of it is motion (vibration, current ripple), not sensor
noise: read the figure as the floor's order of magnitude, not as a bound.

Run: ``.venv/bin/python benchmarks/ur5_real_noise_floor.py ur5-real/`` (the 7 undisturbed movements; a few seconds).
"""

from __future__ import annotations

import argparse

import numpy as np
from ur5_colony_vs_sdp import UNDISTURBED

from estimators.arm.identification import Preparation, load_movements, raw_period
from spaceid_gym.arm.joint_log import ArmLog
from spaceid_gym.arm.signal import lowpass_zero_phase
from spaceid_gym.arrays import FloatArray

#: raw samples dropped at each end, where the zero-phase filter's start-up transient lives
EDGE_SAMPLES = 200


def noise_floor(preparation: Preparation, log: ArmLog) -> tuple[FloatArray, FloatArray, float]:
    """``(sigma_raw_A (n,), floor_percent (n,), overall_percent)`` of one raw movement (module docstring)."""
    dt_s = raw_period(log)
    gain = preparation.noise_gain(dt_s)
    current = np.asarray(log.effort, dtype=float)
    low = lowpass_zero_phase(current, dt_s, preparation.cutoff_hz, preparation.order)
    kept = slice(EDGE_SAMPLES, -EDGE_SAMPLES)
    sigma = (current - low)[kept].std(axis=0) / np.sqrt(1.0 - gain**2)
    floor = sigma * gain
    rms = np.sqrt(np.mean(low[kept] ** 2, axis=0))
    overall = 100.0 * float(np.sqrt(np.sum(floor**2) / np.sum(rms**2)))
    return sigma, 100.0 * floor / rms, overall


def main() -> None:
    """Print one markdown row per movement and the mean over them."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folder", help="folder of the real UR5 movements (ur5-real/)")
    parser.add_argument("--movements", default=",".join(UNDISTURBED), help="comma-separated (default: the 7 undisturbed)")
    args = parser.parse_args()
    names = [name.strip() for name in args.movements.split(",") if name.strip()]
    preparation = Preparation()
    print("| movement | raw white std, A (joints 1-6) | floor %, joint 1 | 2 | 3 | 4 | 5 | 6 | overall |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|")
    floors, overalls = [], []
    for name, log in load_movements(args.folder, names).items():
        sigma, floor, overall = noise_floor(preparation, log)
        floors.append(floor)
        overalls.append(overall)
        cells = " | ".join(f"{value:.1f}" for value in floor)
        print(f"| {name} | {', '.join(f'{s:.3f}' for s in sigma)} | {cells} | {overall:.1f} |")
    mean = " | ".join(f"{value:.1f}" for value in np.mean(floors, axis=0))
    print(f"| **mean** | | {mean} | {np.mean(overalls):.1f} |")


if __name__ == "__main__":
    main()
