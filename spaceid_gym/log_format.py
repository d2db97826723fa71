"""The CSV file of a free-floating measurement log: its columns, reading, writing and the checks of the arrays.

The header is

    t,q1,...,qN,dq1,...,dqN,wx,wy,wz[,qw,qx,qy,qz]

(SI units: s, rad, rad/s; the quaternion is scalar first, base-to-inertial). Values are written
with ``repr`` so a write/read round trip is bit exact, and atomically (:func:`spaceid_gym.files.atomic_open`).
Every input problem raises :class:`~spaceid_gym.errors.SpaceIdInputError` naming the file, the column
and the row. The data class itself is :class:`spaceid_gym.log.MeasurementLog`.
"""

from __future__ import annotations

import csv
from collections.abc import Callable
from pathlib import Path

import numpy as np

from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.files import atomic_open

_OMEGA_COLUMNS = ("wx", "wy", "wz")
_QUAT_COLUMNS = ("qw", "qx", "qy", "qz")
_HEADER_FORMAT = "t,q1,...,qN,dq1,...,dqN,wx,wy,wz[,qw,qx,qy,qz]"


def _column_names(n_joints: int, with_quaternion: bool) -> list[str]:
    """CSV column names for a log with ``n_joints`` joints."""
    names = ["t", *(f"q{i}" for i in range(1, n_joints + 1)), *(f"dq{i}" for i in range(1, n_joints + 1))]
    names += _OMEGA_COLUMNS
    if with_quaternion:
        names += _QUAT_COLUMNS
    return names


def _column_fields(n_joints: int, with_quaternion: bool) -> list[str]:
    """The :class:`MeasurementLog` array element behind each CSV column (for error messages)."""
    fields = ["t_s", *(f"q_rad[:, {i}]" for i in range(n_joints)), *(f"dq_rad_s[:, {i}]" for i in range(n_joints))]
    fields += [f"omega_base_body_rad_s[:, {i}]" for i in range(3)]
    if with_quaternion:
        fields += [f"quat_base_to_inertial_wxyz[:, {i}]" for i in range(4)]
    return fields


def sample_index_label(i: int) -> str:
    """How an error names row ``i`` of arrays that did not come from a file."""
    return f"sample index {i} (0-based)"


def _format_row(values: list[float]) -> str:
    """One CSV line; ``repr`` of a float is the shortest string that reads back bit exact."""
    return ",".join(map(repr, values)) + "\n"


def log_table(t: FloatArray, q: FloatArray, dq: FloatArray, omega: FloatArray, quat: FloatArray | None) -> FloatArray:
    """All columns side by side, shape (T, 1 + 2n + 3 [+ 4]), in CSV column order."""
    parts = [t[:, None], q, dq, omega]
    if quat is not None:
        parts.append(quat)
    return np.hstack(parts)


def check_log_arrays(
    source: str,
    row_label: Callable[[int], str],
    t: FloatArray,
    q: FloatArray,
    dq: FloatArray,
    omega: FloatArray,
    quat: FloatArray | None,
) -> None:
    """Shapes, finiteness, strictly increasing time; errors start with ``source``, rows via ``row_label``."""
    if t.ndim != 1:
        raise SpaceIdInputError(f"{source}: t_s must have shape (T,), got shape {t.shape}")
    n_samples = t.shape[0]
    if n_samples < 1:
        raise SpaceIdInputError(f"{source}: a log needs at least 1 sample, got none")
    if q.ndim != 2 or q.shape[0] != n_samples or q.shape[1] < 1:
        raise SpaceIdInputError(f"{source}: q_rad must have shape (T, n) = ({n_samples}, n) with n >= 1, got shape {q.shape}")
    n = q.shape[1]
    expected_shapes: list[tuple[str, FloatArray | None, tuple[int, int]]] = [
        ("dq_rad_s", dq, (n_samples, n)),
        ("omega_base_body_rad_s", omega, (n_samples, 3)),
        ("quat_base_to_inertial_wxyz", quat, (n_samples, 4)),
    ]
    for name, array, shape in expected_shapes:
        if array is not None and array.shape != shape:
            raise SpaceIdInputError(f"{source}: {name} must have shape {shape}, got shape {array.shape}")

    table = log_table(t, q, dq, omega, quat)
    bad = ~np.isfinite(table)
    if bad.any():
        row = int(np.argmax(bad.any(axis=1)))
        col = int(np.argmax(bad[row]))
        name = _column_names(n, quat is not None)[col]
        field = _column_fields(n, quat is not None)[col]
        raise SpaceIdInputError(
            f"{source}: column '{name}' ({field}) has the non-finite value {float(table[row, col])!r} at "
            f"{row_label(row)}; expected a finite number"
        )
    if quat is not None:
        norm_error = np.abs(np.linalg.norm(quat, axis=1) - 1.0)
        if (norm_error > 1e-6).any():
            i = int(np.argmax(norm_error > 1e-6))
            raise SpaceIdInputError(
                f"{source}: columns 'qw,qx,qy,qz' at {row_label(i)} have norm {float(np.linalg.norm(quat[i]))!r}; "
                "expected a unit quaternion (within 1e-6)"
            )
    not_increasing = np.diff(t) <= 0.0
    if not_increasing.any():
        i = int(np.argmax(not_increasing)) + 1
        raise SpaceIdInputError(
            f"{source}: column 't' must be strictly increasing, but {row_label(i)} has t = {float(t[i])!r} s, "
            f"not greater than t = {float(t[i - 1])!r} s at {row_label(i - 1)}"
        )


def read_log_csv(path: Path, n_joints: int | None = None) -> dict[str, FloatArray | None]:
    """The arrays of the log file ``path``, checked, keyed by the field names of :class:`~spaceid_gym.log.MeasurementLog`.

    What :meth:`MeasurementLog.from_csv <spaceid_gym.log.MeasurementLog.from_csv>` reads through: its arguments and
    its errors (naming the file, the column and the data row with its file line).
    """
    path = Path(path)
    rows, line_numbers = read_csv_rows(path)
    if not rows:
        raise SpaceIdInputError(f"{path}: file is empty; expected a header line '{_HEADER_FORMAT}' and data rows")
    header = [cell.strip() for cell in rows[0]]
    n, with_quat = _parse_header(path, header, line_numbers[0])
    if n_joints is not None and n != n_joints:
        raise SpaceIdInputError(f"{path} has {n} joints (q1..q{n}), the robot has {n_joints}")

    data_rows, data_lines = rows[1:], line_numbers[1:]
    if not data_rows:
        raise SpaceIdInputError(f"{path}: no data rows after the header; a log needs at least 1")

    def row_label(i: int) -> str:
        return f"data row {i + 1} (file line {data_lines[i]})"

    n_columns = len(header)
    table = np.empty((len(data_rows), n_columns), dtype=np.float64)
    for i, row in enumerate(data_rows):
        if len(row) != n_columns:
            raise SpaceIdInputError(f"{path}: {row_label(i)} has {len(row)} values, expected {n_columns} (one per header column)")
        try:
            table[i] = [float(cell) for cell in row]
        except ValueError:
            for j, cell in enumerate(row):
                try:
                    float(cell)
                except ValueError:
                    raise SpaceIdInputError(
                        f"{path}: column '{header[j]}' (column {j + 1}), {row_label(i)}: {cell.strip()!r} is not a number"
                    ) from None
            raise  # pragma: no cover - float() failed on the row but on no single cell
    bad = ~np.isfinite(table)
    if bad.any():
        i = int(np.argmax(bad.any(axis=1)))
        j = int(np.argmax(bad[i]))
        raise SpaceIdInputError(
            f"{path}: column '{header[j]}' (column {j + 1}), {row_label(i)}: {data_rows[i][j].strip()!r} is not a finite number"
        )

    fields = {
        "t_s": table[:, 0],
        "q_rad": table[:, 1 : 1 + n],
        "dq_rad_s": table[:, 1 + n : 1 + 2 * n],
        "omega_base_body_rad_s": table[:, 1 + 2 * n : 4 + 2 * n],
        "quat_base_to_inertial_wxyz": table[:, 4 + 2 * n : 8 + 2 * n] if with_quat else None,
    }
    # Check with file row labels first, so an error names the file line (the constructor's
    # own check then passes).
    check_log_arrays(str(path), row_label, *fields.values())
    return fields


def write_log_csv(path: Path, table: FloatArray, n_joints: int, with_quaternion: bool) -> Path:
    """Write the columns ``table`` (T, 1 + 2n + 3 [+ 4]) under their header, atomically and bit exact; returns ``path``."""
    header = _column_names(n_joints, with_quaternion)
    with atomic_open(path) as f:
        f.write(",".join(header) + "\n")
        for values in table.tolist():
            f.write(_format_row(values))
    return path


def read_csv_rows(path: Path) -> tuple[list[list[str]], list[int]]:
    """Non-blank CSV rows of ``path`` and their 1-based file line numbers."""
    if not path.exists():
        raise SpaceIdInputError(f"{path}: file not found")
    if not path.is_file():
        raise SpaceIdInputError(f"{path}: not a file")
    rows: list[list[str]] = []
    line_numbers: list[int] = []
    try:
        with open(path, encoding="utf-8-sig", newline="") as f:
            reader = csv.reader(f)
            line = 1
            for row in reader:
                if any(cell.strip() for cell in row):
                    rows.append(row)
                    line_numbers.append(line)
                line = reader.line_num + 1
    except UnicodeDecodeError as exc:
        raise SpaceIdInputError(f"{path}: not a UTF-8 text file ({exc.reason} at byte {exc.start})") from exc
    except csv.Error as exc:
        raise SpaceIdInputError(f"{path}: malformed CSV near file line {line}: {exc}") from exc
    except OSError as exc:
        raise SpaceIdInputError(f"{path}: cannot read: {exc.strerror}") from exc
    return rows, line_numbers


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _parse_header(path: Path, header: list[str], line: int) -> tuple[int, bool]:
    """``(n_joints, with_quaternion)`` from the header cells; raise naming the first wrong column."""
    if _is_number(header[0]):
        raise SpaceIdInputError(
            f"{path}: missing header; file line {line} starts with the number {header[0]!r}, "
            f"expected the header '{_HEADER_FORMAT}'"
        )
    # n = number of leading q<k> columns after 't'; the rest of the layout follows from it.
    n = 0
    while 1 + n < len(header) and header[1 + n].startswith("q") and header[1 + n][1:].isdigit():
        n += 1
    if n == 0:
        found = f"is '{header[1]}'" if len(header) > 1 else "is missing"
        if header[0] == "t":
            raise SpaceIdInputError(
                f"{path}: column 2 {found}, expected 'q1' (joint angles q1..qN follow 't'; header format '{_HEADER_FORMAT}')"
            )
    base = _column_names(n, with_quaternion=False)
    for j, expected in enumerate(base):
        if j >= len(header):
            raise SpaceIdInputError(
                f"{path}: column {j + 1} is missing, expected '{expected}' "
                f"(the header ends after column {len(header)} '{header[-1]}'; format '{_HEADER_FORMAT}')"
            )
        if header[j] != expected:
            hint = ""
            if expected.startswith("dq"):
                hint = f" ({n} joint-angle columns q1..q{n} need {n} joint-rate columns dq1..dq{n})"
            raise SpaceIdInputError(f"{path}: column {j + 1} is '{header[j]}', expected '{expected}'{hint}")
    rest = header[len(base) :]
    if not rest:
        return n, False
    if rest == list(_QUAT_COLUMNS):
        return n, True
    if len(rest) < len(_QUAT_COLUMNS) and all(name in _QUAT_COLUMNS for name in rest):
        raise SpaceIdInputError(
            f"{path}: quaternion columns must be all four 'qw,qx,qy,qz' or none; found only '{','.join(rest)}'"
        )
    for k, name in enumerate(rest):
        j = len(base) + k
        if k >= len(_QUAT_COLUMNS):
            raise SpaceIdInputError(
                f"{path}: unexpected column {j + 1} '{name}'; the header ends after 'qz' (format '{_HEADER_FORMAT}')"
            )
        if name != _QUAT_COLUMNS[k]:
            raise SpaceIdInputError(
                f"{path}: column {j + 1} is '{name}', expected '{_QUAT_COLUMNS[k]}' "
                f"(after 'wz' come either no columns or the quaternion 'qw,qx,qy,qz')"
            )
    raise SpaceIdInputError(  # pragma: no cover - every other case is handled above
        f"{path}: quaternion columns must be all four 'qw,qx,qy,qz' or none; found '{','.join(rest)}'"
    )
