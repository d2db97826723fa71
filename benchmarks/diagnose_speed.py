"""Wall time of one ``diagnose`` of a 60 s log next to one plain fit of the same log, and their ratio.

The log is the variation matrix's clean case (:func:`spaceid_gym.variations.draw_variation` of ``none`` and
``--seed``) with ``--robot`` and ``--rate`` pinned, a 5 arcsec star tracker, the diagnostic excitation and the
nominal noise; the model is ``fuel``. The plain fit is ``--estimator`` (default ``lm``, least squares from the
default start) on that model and log. Each figure is the median over ``--repeats`` runs, after one warm-up run of
each (numba kernels compiled or loaded from the cache); every run gets a fresh copy of the log, so that nothing
computed per log carries over from one run to the next. The diagnosis's CPU time (the process's, one thread) is printed
too: on a machine shared with other work the wall time measures the sharing. Usage::

    python benchmarks/diagnose_speed.py [--robot orbit7] [--rate 50] [--repeats 3] [--estimator lm]
"""

from __future__ import annotations

import argparse
import statistics
import time

from estimators.diagnostics.diagnose import diagnose
from estimators.evaluation import estimator_from_spec
from estimators.problem import IdentificationModel
from spaceid_gym.variations import AXIS_VALUES, draw_variation, simulate_variation


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", default="orbit7", choices=AXIS_VALUES["robot"])
    parser.add_argument("--rate", type=int, default=50, choices=AXIS_VALUES["rate_hz"], help="sample rate, Hz")
    parser.add_argument("--seconds", type=float, default=60.0, help="log length")
    parser.add_argument("--seed", type=int, default=3, help="the clean case's seed")
    parser.add_argument("--estimator", default="lm", help="the plain fit (an estimator spec, as in spaceid identify)")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    if args.repeats < 1:
        parser.error(f"--repeats: expected at least 1, got {args.repeats}")
    fixed = {
        "robot": args.robot,
        "rate_hz": args.rate,
        "attitude": "star_tracker_5arcsec",
        "excitation": "diagnostic",
        "noise_scale": 1.0,
    }
    env = simulate_variation(draw_variation("none", args.seed, fixed), args.seconds)
    model = IdentificationModel(env.robot, "fuel")
    log = env.measurement_log()
    print(f"log: {log.n_samples} samples ({log.duration_s:.0f} s at {args.rate} Hz), {args.robot}, clean case seed {args.seed}")

    diagnose(model, env.measurement_log())  # warm-up
    diagnose_times, cpu_times, verdicts = [], [], set()
    for _ in range(args.repeats):
        start, cpu_start = time.perf_counter(), time.process_time()
        verdicts.add(diagnose(model, env.measurement_log()).verdict)
        diagnose_times.append(time.perf_counter() - start)
        cpu_times.append(time.process_time() - cpu_start)

    estimator_from_spec(args.estimator).fit(model, env.measurement_log())  # warm-up
    fit_times = [estimator_from_spec(args.estimator).fit(model, env.measurement_log()).wall_time_s for _ in range(args.repeats)]

    diagnosis, fit = statistics.median(diagnose_times), statistics.median(fit_times)
    print(
        f"diagnose: median {diagnosis:.2f} s (min {min(diagnose_times):.2f}, max {max(diagnose_times):.2f}) over "
        f"{args.repeats} runs, verdict {', '.join(sorted(verdicts))}"
    )
    print(
        f"diagnose CPU time: median {statistics.median(cpu_times):.2f} s (on a shared machine, closer to one free core's wall time)"
    )
    print(f"fit ({args.estimator}, fuel): median {fit:.3f} s (min {min(fit_times):.3f}, max {max(fit_times):.3f})")
    print(f"diagnose / fit: {diagnosis / fit:.0f}")


if __name__ == "__main__":
    main()
