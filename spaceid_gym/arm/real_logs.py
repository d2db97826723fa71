"""Loader for the real UR5 logs (``shared/data/ur5-real/<movement>/``).

A movement folder holds one header-less CSV file per signal, ``<signal>.csv``: column 1 the
controller time (s), columns 2-7 joints 1-6 (base, shoulder, elbow, wrist 1-3), about 125 Hz:

=================  ==========================================================  ======
file               signal                                                      unit
=================  ==========================================================  ======
``q_actual``       measured joint angle                                        rad
``qd_actual``      measured joint rate                                         rad/s
``i_actual``       measured motor current                                      A
``i_target``       current the controller asked for                            A
``m_target``       torque of the controller's own model (a model output)      N m
``qdd_target``     commanded acceleration (no measured acceleration exists)    rad/s^2
=================  ==========================================================  ======

What the loader copes with, and reports per file in :class:`LoadReport`:

* **Truncated last line**: the final line is dropped when it does not end with a newline (even if
  it parses: its last number may be cut short) or when it does not parse. A malformed line
  anywhere else raises :class:`SpaceIdInputError` naming the file and line (a corrupt file is
  not guessed at).
* **NaN / inf values**: the row is dropped (its time stamp then misses in the aligned log).
* **Duplicate or backwards time stamps**: a row whose time is not greater than the last kept
  row's is dropped.
* **Files of different lengths, time stamps that differ slightly between files** (the controller
  writes each file at a slightly different instant, up to ~60 us apart in the older movements):
  rows are matched on time to ``q_actual``'s, nearest neighbour both ways, within a quarter of the
  median period; only time stamps present in every file are kept. The log's time is
  ``q_actual``'s.
* **Jittered sampling** (periods 7.4-24.6 ms in movements No1-No3, exactly 8 ms in the others):
  reported (median, min, max, std, gaps); :func:`spaceid_gym.arm.signal.resample_uniform` makes it
  uniform.

Currents are not torques: ``UR5_TORQUE_CONSTANTS_NM_A`` holds the data author's rough per-joint
slopes (torque constant times gear ratio); identification may stay in current units.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from spaceid_gym.arm.joint_log import ArmLog
from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError

IntArray = NDArray[np.int64]

#: Approximate joint torque per motor current, N m / A, joints 1-6: the rough slopes given by the
#: author of the logs (README of ``shared/data/ur5-real``); not calibrated values.
UR5_TORQUE_CONSTANTS_NM_A: tuple[float, ...] = (7.5, 6.8, 7.1, 2.8, 3.2, 3.4)

#: Effort file -> ArmLog.effort_kind
EFFORT_FILES: dict[str, str] = {"i_actual": "current_A", "i_target": "current_A", "m_target": "torque_Nm"}

_REFERENCE = "q_actual"
_N_JOINTS = 6
_MATCH_FRACTION = 0.25  # match tolerance: this fraction of the reference's median period
_GAP_FACTOR = 1.5  # a step longer than this many median periods is a gap


@dataclass
class FileReport:
    """What happened to one file of a movement.

    Attributes:
        file: the file name.
        rows_read: rows that parsed (before dropping anything).
        truncated_line: the dropped final line's text (``None`` if the file ended cleanly), and its line number.
        nan_lines, duplicate_time_lines, backwards_time_lines: 1-based line numbers of dropped rows.
        unmatched_start, unmatched_end, unmatched_inside: valid rows without a counterpart in every
            other file, before the first kept time stamp, after the last, and in between.
        rows_kept: rows in the loaded log.
    """

    file: str
    rows_read: int = 0
    truncated_line: tuple[int, str] | None = None
    nan_lines: list[int] = field(default_factory=list)
    duplicate_time_lines: list[int] = field(default_factory=list)
    backwards_time_lines: list[int] = field(default_factory=list)
    unmatched_start: int = 0
    unmatched_end: int = 0
    unmatched_inside: int = 0
    rows_kept: int = 0

    @property
    def rows_dropped(self) -> int:
        """Every row (including a truncated last line) that is not in the log."""
        return self.rows_read + (self.truncated_line is not None) - self.rows_kept

    def describe(self) -> str:
        """One line: rows read, kept and why the others were dropped."""
        reasons = []
        if self.truncated_line is not None:
            line, text = self.truncated_line
            shown = text if len(text) <= 40 else text[:37] + "..."
            reasons.append(f"truncated last line {line} ({shown!r})")
        for label, lines in (
            ("NaN", self.nan_lines),
            ("duplicate time", self.duplicate_time_lines),
            ("time going back", self.backwards_time_lines),
        ):
            if lines:
                head = ", ".join(map(str, lines[:5])) + (", ..." if len(lines) > 5 else "")
                reasons.append(f"{len(lines)} {label} (lines {head})")
        unmatched = self.unmatched_start + self.unmatched_end + self.unmatched_inside
        if unmatched:
            reasons.append(
                f"{unmatched} without a common time stamp ({self.unmatched_start} at the start, {self.unmatched_end} at the end, "
                f"{self.unmatched_inside} inside)"
            )
        why = "; ".join(reasons) if reasons else "nothing dropped"
        return f"{self.file}: {self.rows_kept} of {self.rows_read + (self.truncated_line is not None)} rows kept; {why}"


@dataclass
class LoadReport:
    """What :func:`load_ur5_movement` kept and dropped.

    Attributes:
        folder: the movement folder.
        files: per file, in load order (``q_actual``, ``qd_actual``, the effort file).
        n_samples: samples in the log.
        t_start_s, t_end_s: first and last kept time, s (controller time).
        period_median_s, period_mean_s, period_min_s, period_max_s, period_std_s: statistics of the
            kept time steps, s (mean > median when samples are missing: movements No1-No3 alternate
            8 ms and 24 ms steps for most of their length).
        n_gaps: kept time steps longer than 1.5 median periods (missing samples).
        max_time_offset_s: the largest time difference between matched rows of different files, s.
    """

    folder: Path
    files: dict[str, FileReport]
    n_samples: int
    t_start_s: float
    t_end_s: float
    period_median_s: float
    period_mean_s: float
    period_min_s: float
    period_max_s: float
    period_std_s: float
    n_gaps: int
    max_time_offset_s: float

    @property
    def rows_dropped(self) -> dict[str, int]:
        """Rows dropped per file."""
        return {name: report.rows_dropped for name, report in self.files.items()}

    def describe(self) -> str:
        """A few lines for a person: the time base, then one line per file."""
        ms = 1e3
        lines = [
            f"{self.folder.name}: {self.n_samples} samples, t = {self.t_start_s:.3f} .. {self.t_end_s:.3f} s",
            f"  period {self.period_median_s * ms:.3f} ms median, {self.period_mean_s * ms:.3f} ms mean "
            f"(min {self.period_min_s * ms:.3f}, max {self.period_max_s * ms:.3f}, "
            f"std {self.period_std_s * ms:.3f} ms), {self.n_gaps} gaps longer than {_GAP_FACTOR} periods; "
            f"files' time stamps agree within {self.max_time_offset_s * 1e6:.0f} us",
        ]
        lines += [f"  {report.describe()}" for report in self.files.values()]
        return "\n".join(lines)


def list_movements(root: str | Path) -> list[str]:
    """Names of the movement folders under ``root`` (folders holding ``q_actual.csv``), sorted."""
    root = Path(root)
    if not root.is_dir():
        raise SpaceIdInputError(f"{root}: no such folder (expected the folder of UR5 movements)")
    return sorted(p.name for p in root.iterdir() if p.is_dir() and (p / f"{_REFERENCE}.csv").is_file())


def load_ur5_movement(folder: str | Path, effort: str = "i_actual") -> tuple[ArmLog, LoadReport]:
    """Load one real UR5 movement as an :class:`ArmLog` (no accelerations) and say what was dropped.

    Args:
        folder: the movement folder (holding ``q_actual.csv``, ``qd_actual.csv`` and the effort file).
        effort: ``"i_actual"`` (measured current, A; default), ``"i_target"`` (A) or
            ``"m_target"`` (the controller's model torque, N m: a model output, not a measurement).

    Returns:
        The log (time = ``q_actual``'s controller time, s; name = the folder name) and the report.

    Raises:
        SpaceIdInputError: unknown effort, missing folder or file, a malformed line other than the
            last (naming file and line), fewer than 2 valid rows, no common time stamps.
    """
    folder = Path(folder)
    if effort not in EFFORT_FILES:
        raise SpaceIdInputError(f"effort must be one of {sorted(EFFORT_FILES)}, got {effort!r}")
    if not folder.is_dir():
        raise SpaceIdInputError(f"{folder}: no such movement folder")
    names = [_REFERENCE, "qd_actual", effort]
    tables: dict[str, tuple[FloatArray, IntArray]] = {}
    reports: dict[str, FileReport] = {}
    for name in names:
        path = folder / f"{name}.csv"
        if not path.is_file():
            raise SpaceIdInputError(f"{path}: file not found (a movement needs {', '.join(n + '.csv' for n in names)})")
        table, lines, report = _read_joint_file(path)
        tables[name], reports[name] = (table, lines), report

    t_ref = tables[_REFERENCE][0][:, 0]
    tolerance = _MATCH_FRACTION * float(np.median(np.diff(t_ref)))
    # keep[i]: reference row i has a counterpart in every file; row_of[name][i]: that file's row
    keep = np.ones(t_ref.size, dtype=bool)
    row_of: dict[str, IntArray] = {_REFERENCE: np.arange(t_ref.size)}
    for name in names[1:]:
        ref_idx, other_idx = _match_times(t_ref, tables[name][0][:, 0], tolerance)
        rows = np.full(t_ref.size, -1)
        rows[ref_idx] = other_idx
        row_of[name] = rows
        keep &= rows >= 0
    if keep.sum() < 2:
        raise SpaceIdInputError(
            f"{folder}: the files share {int(keep.sum())} time stamps (matched within {tolerance * 1e3:.2f} ms); need at least 2"
        )

    kept_rows = {name: row_of[name][keep] for name in names}
    max_offset = max(float(np.max(np.abs(tables[name][0][kept_rows[name], 0] - t_ref[keep]))) for name in names)
    for name in names:
        _count_unmatched(reports[name], tables[name][0].shape[0], kept_rows[name])

    def columns(name: str) -> FloatArray:
        return tables[name][0][kept_rows[name], 1:]

    t = t_ref[keep]
    log = ArmLog(
        t_s=t,
        q_rad=columns(_REFERENCE),
        dq_rad_s=columns("qd_actual"),
        ddq_rad_s2=None,
        effort=columns(effort),
        effort_kind=EFFORT_FILES[effort],
        name=folder.name,
    )
    step = np.diff(t)
    median = float(np.median(step))
    report = LoadReport(
        folder=folder,
        files=reports,
        n_samples=log.n_samples,
        t_start_s=float(t[0]),
        t_end_s=float(t[-1]),
        period_median_s=median,
        period_mean_s=float(step.mean()),
        period_min_s=float(step.min()),
        period_max_s=float(step.max()),
        period_std_s=float(step.std()),
        n_gaps=int(np.count_nonzero(step > _GAP_FACTOR * median)),
        max_time_offset_s=max_offset,
    )
    return log, report


def _read_joint_file(path: Path, n_joints: int = _N_JOINTS) -> tuple[FloatArray, IntArray, FileReport]:
    """Parse a header-less ``time, joint 1..n`` file: (valid rows (R, 1 + n), their 1-based lines (R,), report)."""
    report = FileReport(file=path.name)
    try:
        text = path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as exc:
        raise SpaceIdInputError(f"{path}: not a text file (undecodable byte at offset {exc.start})") from None
    except OSError as exc:
        raise SpaceIdInputError(f"{path}: cannot read: {exc.strerror}") from None
    raw_lines = text.split("\n")  # the last element is "" iff the file ends with a newline
    numbered = [(k + 1, line.strip()) for k, line in enumerate(raw_lines) if line.strip()]
    if not numbered:
        raise SpaceIdInputError(f"{path}: file is empty; expected rows 'time, joint 1, ..., joint {n_joints}'")
    last_unterminated = raw_lines[-1].strip() != ""
    values: list[list[float]] = []
    lines: list[int] = []
    for position, (line_number, line) in enumerate(numbered):
        is_last = position == len(numbered) - 1
        if is_last and last_unterminated:
            report.truncated_line = (line_number, line)
            break
        parsed = _parse_row(line, n_joints)
        if isinstance(parsed, str):
            if is_last:
                report.truncated_line = (line_number, line)
                break
            raise SpaceIdInputError(f"{path}, line {line_number}: {parsed}; expected 'time, joint 1, ..., joint {n_joints}'")
        values.append(parsed)
        lines.append(line_number)
    table = np.array(values, dtype=float).reshape(-1, 1 + n_joints)
    line_numbers = np.array(lines, dtype=np.int64)
    report.rows_read = table.shape[0]

    finite = np.isfinite(table).all(axis=1)
    report.nan_lines = line_numbers[~finite].tolist()
    table, line_numbers = table[finite], line_numbers[finite]

    t = table[:, 0]
    running_max = np.maximum.accumulate(t) if t.size else t
    previous_max = np.concatenate([[-np.inf], running_max[:-1]])
    ordered = t > previous_max  # keep a row only if its time exceeds every earlier one
    report.duplicate_time_lines = line_numbers[t == previous_max].tolist()
    report.backwards_time_lines = line_numbers[t < previous_max].tolist()
    table, line_numbers = table[ordered], line_numbers[ordered]
    if table.shape[0] < 2:
        raise SpaceIdInputError(f"{path}: only {table.shape[0]} valid row(s) (of {report.rows_read} read); need at least 2")
    return table, line_numbers, report


def _parse_row(line: str, n_joints: int) -> list[float] | str:
    """The row's numbers, or a description of what is wrong with it."""
    cells = line.split(",")
    if len(cells) != 1 + n_joints:
        return f"{len(cells)} values, expected {1 + n_joints}"
    try:
        return [float(cell) for cell in cells]
    except ValueError:
        bad = next(cell for cell in cells if not _is_float(cell))
        return f"{bad.strip()!r} is not a number"


def _is_float(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _match_times(t_ref: FloatArray, t_other: FloatArray, tolerance: float) -> tuple[IntArray, IntArray]:
    """Pairs (i, j) with ``t_other[j]`` the nearest to ``t_ref[i]`` and vice versa, within ``tolerance`` (both increasing)."""

    def nearest(t_from: FloatArray, t_to: FloatArray) -> IntArray:
        right = np.clip(np.searchsorted(t_to, t_from), 1, t_to.size - 1)
        left = right - 1
        return np.where(np.abs(t_from - t_to[left]) <= np.abs(t_to[right] - t_from), left, right)

    j = nearest(t_ref, t_other)
    i_back = nearest(t_other, t_ref)
    mutual = (i_back[j] == np.arange(t_ref.size)) & (np.abs(t_other[j] - t_ref) <= tolerance)
    i = np.flatnonzero(mutual)
    return i, j[i]


def _count_unmatched(report: FileReport, n_rows: int, kept: IntArray) -> None:
    """Fill the unmatched counts of ``report`` given the kept row indices (increasing) of its valid rows."""
    report.rows_kept = int(kept.size)
    report.unmatched_start = int(kept[0])
    report.unmatched_end = int(n_rows - 1 - kept[-1])
    report.unmatched_inside = int(n_rows - kept.size - report.unmatched_start - report.unmatched_end)
