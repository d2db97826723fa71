"""Joint logs of a fixed-base arm: :class:`ArmLog` and its CSV file.

An :class:`ArmLog` holds T samples of an n-joint arm: time, joint angles, rates, optionally
accelerations (real logs have none measured: :mod:`spaceid_gym.arm.signal` derives them), and the
joint effort, either torque (N m) or motor current (A). Its CSV file has the header

    t,q1,...,qN,dq1,...,dqN[,ddq1,...,ddqN],tau1,...,tauN      (effort_kind "torque_Nm")
    t,q1,...,qN,dq1,...,dqN[,ddq1,...,ddqN],i1,...,iN          (effort_kind "current_A")

in SI units (s, rad, rad/s, rad/s^2, N m or A), values written with ``repr`` (bit-exact round
trip), atomically (temporary file, then rename). The log's ``name`` is not stored in the file;
:meth:`ArmLog.from_csv` uses the file name's stem unless told otherwise.
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.files import atomic_open
from spaceid_gym.log import JointTimeSeries
from spaceid_gym.log_format import read_csv_rows

PathLike = str | os.PathLike[str]

#: effort kind -> CSV column prefix
EFFORT_KINDS: dict[str, str] = {"torque_Nm": "tau", "current_A": "i"}
_HEADER_FORMAT = "t,q1..qN,dq1..dqN[,ddq1..ddqN],tau1..tauN (or i1..iN for currents)"
_FIELDS = ("t_s", "q_rad", "dq_rad_s", "ddq_rad_s2", "effort")


@dataclass(frozen=True, eq=False, repr=False)
class ArmLog(JointTimeSeries):
    """T samples of an n-joint fixed-base arm.

    The constructor copies the arrays to read-only float64 arrays and validates them.

    Attributes:
        t_s: time, shape (T,), s, strictly increasing, T >= 1.
        q_rad: joint angles, shape (T, n), rad.
        dq_rad_s: joint rates, shape (T, n), rad/s.
        ddq_rad_s2: joint accelerations, shape (T, n), rad/s^2, or ``None`` (not measured).
        effort: joint torques (N m) or motor currents (A), shape (T, n), see ``effort_kind``.
        effort_kind: ``"torque_Nm"`` or ``"current_A"``.
        name: a label (movement name, file stem); starts error messages.
    """

    t_s: FloatArray
    q_rad: FloatArray
    dq_rad_s: FloatArray
    ddq_rad_s2: FloatArray | None
    effort: FloatArray
    effort_kind: str = "torque_Nm"
    name: str = ""

    def __post_init__(self) -> None:
        self._freeze_arrays(_FIELDS, ("ddq_rad_s2",), self._source())
        self.validate()

    def __repr__(self) -> str:
        return (
            f"ArmLog({self.name!r}, n_samples={self.n_samples}, n_joints={self.n_joints}, "
            f"t=[{self.t_s[0]:g}, {self.t_s[-1]:g}] s, effort={self.effort_kind}, ddq={'yes' if self.ddq_rad_s2 is not None else 'no'})"
        )

    def _source(self) -> str:
        return f"ArmLog {self.name!r}" if self.name else "ArmLog"

    def column_names(self) -> list[str]:
        """The CSV header of this log (see the module docstring)."""
        return _column_names(self.n_joints, self.ddq_rad_s2 is not None, self.effort_kind)

    def table(self) -> FloatArray:
        """All columns side by side in CSV order, shape (T, 2 + 3n or 2 + 4n)."""
        parts = [self.t_s[:, None], self.q_rad, self.dq_rad_s]
        if self.ddq_rad_s2 is not None:
            parts.append(self.ddq_rad_s2)
        parts.append(self.effort)
        return np.hstack(parts)

    # ------------------------------------------------------------------ validation
    def validate(self, source: str | None = None) -> ArmLog:
        """Check shapes, the effort kind, finite values and strictly increasing time; return ``self``.

        Raises:
            SpaceIdInputError: naming ``source`` (default: the log's name), the column and the sample index.
        """
        source = source or self._source()
        if self.effort_kind not in EFFORT_KINDS:
            raise SpaceIdInputError(f"{source}: effort_kind must be one of {sorted(EFFORT_KINDS)}, got {self.effort_kind!r}")
        if self.t_s.ndim != 1 or self.t_s.shape[0] < 1:
            raise SpaceIdInputError(f"{source}: t_s must have shape (T,) with T >= 1, got shape {self.t_s.shape}")
        T = self.t_s.shape[0]
        if self.q_rad.ndim != 2 or self.q_rad.shape[0] != T or self.q_rad.shape[1] < 1:
            raise SpaceIdInputError(
                f"{source}: q_rad must have shape (T, n) = ({T}, n) with n >= 1, got shape {self.q_rad.shape}"
            )
        n = self.q_rad.shape[1]
        for field in ("dq_rad_s", "ddq_rad_s2", "effort"):
            array = getattr(self, field)
            if array is not None and array.shape != (T, n):
                raise SpaceIdInputError(f"{source}: {field} must have shape ({T}, {n}) like q_rad, got shape {array.shape}")
        table = self.table()
        bad = ~np.isfinite(table)
        if bad.any():
            row = int(np.argmax(bad.any(axis=1)))
            col = int(np.argmax(bad[row]))
            raise SpaceIdInputError(
                f"{source}: column '{self.column_names()[col]}' has the non-finite value {float(table[row, col])!r} "
                f"at sample index {row} (0-based); expected a finite number"
            )
        step = np.diff(self.t_s)
        if (step <= 0).any():
            i = int(np.argmax(step <= 0)) + 1
            raise SpaceIdInputError(
                f"{source}: column 't' must be strictly increasing, but sample index {i} has t = {float(self.t_s[i])!r} s, "
                f"not greater than {float(self.t_s[i - 1])!r} s before it"
            )
        return self

    # ------------------------------------------------------------------ derived logs
    def select(self, index: slice | NDArray[np.bool_] | NDArray[np.int64]) -> ArmLog:
        """The samples ``index`` selects (a slice, a boolean mask of shape (T,) or increasing indices), as a new log."""
        ddq = None if self.ddq_rad_s2 is None else self.ddq_rad_s2[index]
        return dataclasses.replace(
            self,
            t_s=self.t_s[index],
            q_rad=self.q_rad[index],
            dq_rad_s=self.dq_rad_s[index],
            ddq_rad_s2=ddq,
            effort=self.effort[index],
        )

    # ------------------------------------------------------------------ CSV
    def to_csv(self, path: PathLike) -> Path:
        """Write the log as CSV (header in the module docstring), bit exact and atomically; returns the path."""
        path = Path(path)
        with atomic_open(path) as f:
            f.write(",".join(self.column_names()) + "\n")
            for values in self.table().tolist():
                f.write(",".join(map(repr, values)) + "\n")
        return path

    @classmethod
    def from_csv(cls, path: PathLike, n_joints: int | None = None, name: str | None = None) -> ArmLog:
        """Read a log written by :meth:`to_csv` (or by hand in the same format).

        Args:
            path: the CSV file.
            n_joints: if given, the file must have this many joints.
            name: the log's name (default: the file name's stem).

        Raises:
            SpaceIdInputError: naming the file and, where relevant, the column and the file line.
        """
        path = Path(path)
        rows, lines = read_csv_rows(path)
        if not rows:
            raise SpaceIdInputError(f"{path}: file is empty; expected the header '{_HEADER_FORMAT}' and data rows")
        header = [cell.strip() for cell in rows[0]]
        n, with_ddq, kind = _parse_header(path, header)
        if n_joints is not None and n != n_joints:
            raise SpaceIdInputError(f"{path} has {n} joints (q1..q{n}), expected {n_joints}")
        if len(rows) < 2:
            raise SpaceIdInputError(f"{path}: no data rows after the header; a log needs at least 1")
        table = np.empty((len(rows) - 1, len(header)))
        for i, row in enumerate(rows[1:]):
            if len(row) != len(header):
                raise SpaceIdInputError(
                    f"{path}, line {lines[i + 1]}: {len(row)} values, expected {len(header)} (one per header column)"
                )
            for j, cell in enumerate(row):
                try:
                    table[i, j] = float(cell)
                except ValueError:
                    raise SpaceIdInputError(
                        f"{path}, line {lines[i + 1]}, column '{header[j]}': {cell.strip()!r} is not a number"
                    ) from None
        bad = ~np.isfinite(table)
        if bad.any():
            i = int(np.argmax(bad.any(axis=1)))
            j = int(np.argmax(bad[i]))
            raise SpaceIdInputError(
                f"{path}, line {lines[i + 1]}, column '{header[j]}': {rows[i + 1][j].strip()!r} is not a finite number"
            )
        step = np.diff(table[:, 0])
        if (step <= 0).any():
            i = int(np.argmax(step <= 0)) + 1
            raise SpaceIdInputError(
                f"{path}, line {lines[i + 1]}, column 't': {table[i, 0]!r} s is not greater than {table[i - 1, 0]!r} s "
                f"on line {lines[i]}; time must be strictly increasing"
            )
        blocks = np.split(table[:, 1:], 4 if with_ddq else 3, axis=1)
        return cls(
            t_s=table[:, 0],
            q_rad=blocks[0],
            dq_rad_s=blocks[1],
            ddq_rad_s2=blocks[2] if with_ddq else None,
            effort=blocks[-1],
            effort_kind=kind,
            name=path.stem if name is None else name,
        )


def _column_names(n: int, with_ddq: bool, effort_kind: str) -> list[str]:
    prefixes = ["q", "dq", *(["ddq"] if with_ddq else []), EFFORT_KINDS[effort_kind]]
    return ["t", *(f"{prefix}{j}" for prefix in prefixes for j in range(1, n + 1))]


def _parse_header(path: Path, header: list[str]) -> tuple[int, bool, str]:
    """``(n_joints, with_ddq, effort_kind)`` from the header; raise naming the first wrong column."""
    try:
        float(header[0])
    except ValueError:
        pass
    else:
        raise SpaceIdInputError(f"{path}: missing header; line 1 starts with a number, expected '{_HEADER_FORMAT}'")
    n = 0
    while 1 + n < len(header) and header[1 + n] == f"q{n + 1}":
        n += 1
    if n == 0:
        raise SpaceIdInputError(f"{path}: the header must start 't,q1', got {','.join(header[:2])!r} (format '{_HEADER_FORMAT}')")
    with_ddq = len(header) > 1 + 2 * n and header[1 + 2 * n] == "ddq1"
    effort_column = header[1 + (3 if with_ddq else 2) * n] if len(header) > 1 + (3 if with_ddq else 2) * n else ""
    kind = next((k for k, prefix in EFFORT_KINDS.items() if effort_column == f"{prefix}1"), "torque_Nm")
    expected = _column_names(n, with_ddq, kind)
    for j, name in enumerate(expected):
        if j >= len(header) or header[j] != name:
            found = f"'{header[j]}'" if j < len(header) else "missing"
            raise SpaceIdInputError(f"{path}: column {j + 1} is {found}, expected '{name}' (format '{_HEADER_FORMAT}')")
    if len(header) > len(expected):
        raise SpaceIdInputError(
            f"{path}: unexpected column {len(expected) + 1} '{header[len(expected)]}' after '{expected[-1]}' (format '{_HEADER_FORMAT}')"
        )
    return n, with_ddq, kind
