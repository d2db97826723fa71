"""Presliding (Dahl) friction on real UR5 data no choice has seen: the two movements with pushes, outside the pushes.

The rules below were written down before any candidate's error on these movements was computed.

**Test data**: ``Movement_No5_Acc_slow_w_disturbance`` and ``Movement_No9_Singularity_Free_WDist``, prepared by the
identification's chain (:class:`~estimators.arm.identification.Preparation`: 4 Hz zero-phase low-pass, parallel
filtering, edges dropped, decimation by 5), with the samples near a push masked. No model, length or rule of the
candidates was chosen on them. Each repeats the commanded trajectory of an undisturbed movement of the training set
(its twin, :data:`TWIN`): fresh recordings of seen trajectories, not new trajectories.

**The mask** uses none of the candidates: the controller's own current command ``i_target`` (logged, never fitted
here). A person's push is resisted by the joint controllers, so the measured current leaves the command. Per joint the
deviation ``d = i_actual - i_target`` goes through the same chain (so it lies on the test samples); a sample is over
the limit where for any joint ``|d_j - c_j| > L_j``, with ``c_j`` the median of ``d_j`` over the prepared samples of
the 7 undisturbed movements and ``L_j`` the largest ``|d_j - c_j|`` there (:func:`push_threshold`): the sample's
deviation exceeds every one seen without a push (the command lacks friction, so ``d`` is not small in normal motion;
a limit from the undisturbed spread rather than a multiple of a noise std). Every sample within :data:`MARGIN_S` of
one over the limit is masked, all joints at once (an external force acts on every joint): the limit is crossed only
near a push's peak, the push's rise and the filter's spread (its impulse response is about 0.25 s wide at 4 Hz) lie
before and after it; a kept stretch shorter than :data:`MIN_KEPT_S` between two masked ones is masked too (the
deviation dipping under the limit within one push). Printed: the masked intervals and the share masked, and as a check each undisturbed movement's share masked with the
limit of the other six. It may favour (d) slightly: the samples
where the controller's model misses most are masked, and (d) is that model refitted; it cannot favour (b) over (a).

**Candidates**, fitted on all 7 undisturbed movements with the model asymmetric Coulomb + viscous + armature, rules
fixed before: (a) ``sdp`` (the standing model); (b) ``sdp`` with ``dahl_per_joint`` as the screening defines it
(``ur5_presliding.choose_lengths``: per joint a presliding length or the Coulomb column, by the WLS training cost);
(c) ``sdp`` with ``dahl`` (every joint); (d) UR's refitted model with the same friction and an offset (the target).
**Error**: ``100 ||e|| / ||i||`` over the kept samples (as ``arm cross-validate``), per movement, per joint and over
both movements pooled. Secondary, also fixed before: each movement predicted by fits without its twin (6 movements),
a test on an unseen trajectory too.

**Interval** of the differences (b)-(a) and (b)-(d) of the pooled error: a block bootstrap over time, non-overlapping
blocks of :data:`BLOCK_S` s (2 s, primary) resampled with replacement within each movement (:data:`DRAWS` draws,
seed 0), the error recomputed from the blocks' sums of squares; 95 % percentile interval. 2 s: the residual is
correlated over far more than the filter's 0.25 s (it follows the motion), and one block must not be a whole cycle of
the No5 movement (6 s) or too few blocks remain (about 10 per movement); 1 s and 4 s are printed as a check.
A difference counts as a win only where its interval lies below 0.

Run: ``.venv/bin/python benchmarks/ur5_fresh_movements.py ur5-real/`` (``--mask-only``: the mask alone; ``--margin``:
another margin, a check added after the first run).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from collections.abc import Mapping, Sequence

import numpy as np
from ur5_colony_vs_sdp import UNDISTURBED
from ur5_extra_terms import OursScreen, relative_error, ur_screen
from ur5_presliding import choose_lengths, lengths_text, presliding_columns
from ur5_presliding_sdp import substituted

from estimators.arm.identification import Preparation, fit, load_movements, physically_consistent
from estimators.arm.model import ArmIdentificationModel
from estimators.evaluation import estimator_from_spec
from spaceid_gym.arm.arm_robot import load_arm
from spaceid_gym.arm.joint_log import ArmLog
from spaceid_gym.arm.signal import prepare_for_identification
from spaceid_gym.arrays import FloatArray

#: the movements with pushes and their undisturbed twins (the same commanded trajectory)
TWIN = {
    "Movement_No5_Acc_slow_w_disturbance": "Movement_No5_Acc_slow_no_disturbance",
    "Movement_No9_Singularity_Free_WDist": "Movement_No9_Singularity_Free_NoDist",
}
DISTURBED = tuple(TWIN)
#: samples within this time of one over the limit are masked, s (module docstring)
MARGIN_S = 0.5
#: a kept stretch shorter than this between two masked ones is masked too, s (module docstring)
MIN_KEPT_S = 1.0
#: bootstrap block lengths, s: the first is the primary one
BLOCK_S = (2.0, 1.0, 4.0)
DRAWS = 4000
#: the candidates' labels: (a)-(c) the Dahl choice given to ``choose_lengths`` (``None``: the model's Coulomb columns)
OURS = {"(a) sdp": None, "(b) sdp + dahl_per_joint": "dahl_per_joint", "(c) sdp + dahl": "dahl"}
UR_LABEL = "(d) UR refitted"


@dataclasses.dataclass(frozen=True)
class PushThreshold:
    """Per joint (n,) the centre and the limit of ``i_actual - i_target``, A (module docstring)."""

    centre_A: FloatArray
    limit_A: FloatArray


def deviation_log(current: ArmLog, command: ArmLog, preparation: Preparation) -> ArmLog:
    """The prepared log whose effort is ``i_actual - i_target`` (A) of a raw ``current`` log and its raw ``command``
    (``i_target``) log, on the identification's samples."""
    target = np.stack([np.interp(current.t_s, command.t_s, command.effort[:, j]) for j in range(current.n_joints)], axis=1)
    deviation = dataclasses.replace(current, effort=current.effort - target)
    return prepare_for_identification(deviation, preparation.cutoff_hz, preparation.decimate_factor, preparation.order)


def controller_deviation(data: str, logs: Mapping[str, ArmLog], preparation: Preparation) -> dict[str, ArmLog]:
    """:func:`deviation_log` of every movement of ``logs`` (raw current logs of the real movements in ``data``)."""
    commands = load_movements(data, list(logs), effort="i_target")
    return {name: deviation_log(log, commands[name], preparation) for name, log in logs.items()}


def push_threshold(deviations: Sequence[FloatArray]) -> PushThreshold:
    """The centre (median) and limit (largest distance from it) per joint of the undisturbed ``deviations`` (T, n)."""
    stacked = np.concatenate(deviations)
    centre = np.median(stacked, axis=0)
    return PushThreshold(centre, np.abs(stacked - centre).max(axis=0))


def push_mask(t_s: FloatArray, deviation: FloatArray, threshold: PushThreshold, margin_s: float = MARGIN_S) -> FloatArray:
    """(T,) True where a sample is masked: within ``margin_s`` of a sample whose deviation (T, n) is over the limit."""
    over = t_s[(np.abs(deviation - threshold.centre_A) > threshold.limit_A).any(axis=1)]
    if over.size == 0:
        return np.zeros(t_s.shape, dtype=bool)
    after = np.searchsorted(over, t_s)
    left, right = over[np.clip(after - 1, 0, over.size - 1)], over[np.clip(after, 0, over.size - 1)]
    masked = np.minimum(np.abs(t_s - left), np.abs(t_s - right)) <= margin_s + 1e-9
    for start, end in intervals(t_s, ~masked):
        if start > t_s[0] and end < t_s[-1] and end - start < MIN_KEPT_S:
            masked[(t_s >= start) & (t_s <= end)] = True
    return masked


def intervals(t_s: FloatArray, masked: FloatArray) -> list[tuple[float, float]]:
    """The masked stretches as (first, last) sample times, s."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], masked.astype(int), [0]])))
    return [(float(t_s[a]), float(t_s[b - 1])) for a, b in zip(edges[::2], edges[1::2], strict=True)]


def masks(data: str, logs: Mapping[str, ArmLog], preparation: Preparation, margin_s: float = MARGIN_S) -> dict[str, FloatArray]:
    """The mask of each disturbed movement of ``logs``, the limit from its undisturbed ones; printed with its intervals."""
    deviation = controller_deviation(data, logs, preparation)
    threshold = push_threshold([deviation[name].effort for name in UNDISTURBED])
    print(f"mask: centre A {np.round(threshold.centre_A, 3)}, limit A {np.round(threshold.limit_A, 3)}, margin {margin_s} s")
    for name in UNDISTURBED:  # the check: each undisturbed movement with the limit of the other six
        others = push_threshold([deviation[other].effort for other in UNDISTURBED if other != name])
        share = push_mask(deviation[name].t_s, deviation[name].effort, others, margin_s).mean()
        print(f"  {name} against the limit of the other six: masked {100 * share:.1f} %")
    out = {}
    for name in DISTURBED:
        log = deviation[name]
        out[name] = push_mask(log.t_s, log.effort, threshold, margin_s)
        stretches = ", ".join(f"{a:.2f}-{b:.2f}" for a, b in intervals(log.t_s, out[name]))
        print(f"  {name}: masked {100 * out[name].mean():.1f} % of {log.t_s.size} samples ({stretches} s)")
    return out


def predictions(
    screen: OursScreen, data: str, logs: Mapping[str, ArmLog], preparation: Preparation, train: Sequence[str]
) -> dict[str, dict[str, FloatArray]]:
    """Per candidate (module docstring) fitted on ``train``, its prediction (T, n) of each disturbed movement."""
    model, estimator, out = screen.model, estimator_from_spec("sdp", seed=0), {}
    for label, dahl in OURS.items():
        choice = np.full(model.n_joints, -1) if dahl is None else choose_lengths(screen, train, dahl)
        estimate = fit(model, {name: substituted(screen, name, choice) for name in train}, estimator)
        out[label] = {name: model.predict(estimate.theta, substituted(screen, name, choice)) for name in DISTURBED}
        print(f"  {label}: presliding lengths (rad) {lengths_text(choice)}; consistent {physically_consistent(estimate)}")
    ur = ur_screen(model, data, dict(logs), preparation)
    if any(not np.array_equal(ur.effort(name), screen.effort(name)) for name in DISTURBED):
        raise RuntimeError("UR's refitted model and ours do not see the same prepared samples")
    theta, _ = ur.fit(train, "none")
    out[UR_LABEL] = {name: ur.predict(ur.design(name), theta) for name in DISTURBED}
    return out


def block_sums(effort: FloatArray, residual: FloatArray, t_s: FloatArray, keep: FloatArray, block_s: float) -> FloatArray:
    """(B, 2) per time block of ``block_s`` the kept samples' sums of ``effort**2`` and ``residual**2`` (T, n)."""
    block = ((t_s - t_s[0]) // block_s).astype(int)[keep]
    size = block.max() + 1
    sums = [np.bincount(block, np.sum(x[keep] ** 2, axis=1), minlength=size) for x in (effort, residual)]
    return np.stack(sums, axis=1)[np.bincount(block, minlength=size) > 0]


def bootstrap(
    sums: Mapping[str, Mapping[str, FloatArray]], pairs: Sequence[tuple[str, str]], held: Sequence[str], seed: int = 0
) -> None:
    """The 95 % interval of the difference of the errors pooled over ``held`` per pair, blocks resampled within each
    movement; ``sums`` by candidate and movement (B, 2) from :func:`block_sums`."""
    rng = np.random.default_rng(seed)
    draws = {name: rng.integers(0, len(block), (DRAWS, len(block))) for name, block in next(iter(sums.values())).items()}
    draws = {name: draws[name] for name in held}

    def pooled(label: str) -> FloatArray:
        effort = sum(sums[label][name][index, 0].sum(axis=1) for name, index in draws.items())
        error = sum(sums[label][name][index, 1].sum(axis=1) for name, index in draws.items())
        return 100.0 * np.sqrt(error / effort)

    for first, second in pairs:
        difference = pooled(first) - pooled(second)
        low, high = np.percentile(difference, [2.5, 97.5])
        print(
            f"    {first[:3]}-{second[:3]} {'+'.join(name.split('_')[1] for name in held)}: 95 % [{low:+.2f}, {high:+.2f}] "
            f"points, below 0 in {100 * np.mean(difference < 0):.1f} %"
        )


def correlation_zero(x: FloatArray) -> int:
    """The first lag (samples) at which the autocorrelation of ``x`` (T,) falls below 0."""
    x = x - x.mean()
    return int(np.argmax(np.correlate(x, x, "full")[x.size - 1 :] < 0))


def report(
    predicted: Mapping[str, Mapping[str, FloatArray]], screen: OursScreen, kept: Mapping[str, FloatArray], held: Sequence[str]
) -> None:
    """Per candidate the error on the kept samples of each movement of ``held`` and pooled; the bootstrap intervals."""
    for label, by_name in predicted.items():
        cells = []
        for name in held:
            overall, joints = relative_error(screen.rows[name].log.effort[kept[name]], by_name[name][kept[name]])
            cells.append(f"{name.split('_')[1]} {overall:6.2f} % (joints {' '.join(f'{v:5.1f}' for v in joints)})")
        effort = np.concatenate([screen.rows[name].log.effort[kept[name]] for name in held])
        pooled, _ = relative_error(effort, np.concatenate([by_name[name][kept[name]] for name in held]))
        print(f"  {label:<26} pooled {pooled:6.2f} %  " + "  ".join(cells))
    pairs = [("(b) sdp + dahl_per_joint", "(a) sdp"), ("(b) sdp + dahl_per_joint", UR_LABEL), ("(c) sdp + dahl", "(a) sdp")]
    for name in held:  # the block length's check: the correlation of the compared quantity on the longest kept stretch
        stretch = max(np.split(np.flatnonzero(kept[name]), np.flatnonzero(np.diff(np.flatnonzero(kept[name])) > 1) + 1), key=len)
        log = screen.rows[name].log
        gain = np.sum((log.effort - predicted[pairs[0][0]][name]) ** 2 - (log.effort - predicted[pairs[0][1]][name]) ** 2, axis=1)
        lag = correlation_zero(gain[stretch]) * float(np.median(np.diff(log.t_s)))
        print(f"  {name}: autocorrelation of the (b)-(a) squared-error difference first below 0 at {lag:.2f} s")
    for block_s in BLOCK_S:
        print(f"  block bootstrap, {block_s} s blocks, {DRAWS} draws:")
        sums = {
            label: {
                name: block_sums((log := screen.rows[name].log).effort, log.effort - by_name[name], log.t_s, kept[name], block_s)
                for name in held
            }
            for label, by_name in predicted.items()
        }
        bootstrap(sums, pairs, held)
        if block_s == BLOCK_S[0] and len(held) > 1:  # each movement alone, the same draws
            for name in held:
                bootstrap(sums, pairs, [name])


def main() -> None:
    """The mask, then the candidates fitted on all 7 undisturbed movements, then on the 6 without each twin."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("data", help="folder of the real UR5 movements (shared/data/ur5-real)")
    parser.add_argument("--mask-only", action="store_true", help="print the mask and stop")
    parser.add_argument("--margin", type=float, default=MARGIN_S, help=f"the mask's margin, s (default {MARGIN_S}; a check)")
    args = parser.parse_args()
    print("command: .venv/bin/python benchmarks/ur5_fresh_movements.py " + " ".join(sys.argv[1:]))
    model = ArmIdentificationModel.build(load_arm("ur5"), ("coulomb_asymmetric", "viscous"), armature=True)
    preparation = Preparation()
    logs = load_movements(args.data, [*UNDISTURBED, *DISTURBED])
    kept = {name: ~mask for name, mask in masks(args.data, logs, preparation, args.margin).items()}
    if args.mask_only:
        return
    screen = OursScreen(model, preparation.all_rows(model, logs))
    screen.presliding = {name: presliding_columns(model, log, preparation) for name, log in logs.items()}
    print("\nfitted on the 7 undisturbed movements (primary):")
    report(predictions(screen, args.data, logs, preparation, UNDISTURBED), screen, kept, DISTURBED)
    for name, twin in TWIN.items():
        print(f"\nfitted on the 6 without {twin} (secondary), {name}:")
        train = [other for other in UNDISTURBED if other != twin]
        report(predictions(screen, args.data, logs, preparation, train), screen, kept, [name])


if __name__ == "__main__":
    main()
