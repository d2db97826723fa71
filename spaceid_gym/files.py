"""Files written whole or not at all, and values made ready for JSON.

Every output file of the toolkit is written atomically: a temporary file in the same folder, flushed, then
``os.replace``-d over the target, so an error or a Ctrl-C never leaves a half-written file.
:func:`json_value` turns numpy arrays and scalars, tuples and paths into JSON types and rejects what JSON cannot
hold; :func:`jsonable` is its lenient form for reports (non-finite numbers become ``None``, anything else unknown is
left as it is).
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import secrets
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from pathlib import Path
from typing import Any

import numpy as np

from spaceid_gym.errors import SpaceIdInputError

PathLike = str | os.PathLike[str]


# ---------------------------------------------------------------------- atomic writes
@contextmanager
def atomic_open(path: PathLike, binary: bool = False) -> Iterator[Any]:
    """Open a temporary file next to ``path`` for writing (text UTF-8, or ``binary``); on success rename it over ``path``.

    On any exception the temporary file is removed and ``path`` keeps its previous content (or stays
    absent); a missing or unwritable folder raises :class:`SpaceIdInputError`.
    """
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{secrets.token_hex(4)}.tmp")
    try:
        f = open(tmp, "xb") if binary else open(tmp, "x", encoding="utf-8", newline="\n")  # noqa: SIM115 - closed below
    except OSError as exc:
        raise SpaceIdInputError(f"{path}: cannot write: {exc.strerror}") from exc
    try:
        with f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        with suppress(OSError):
            tmp.unlink()
        raise


def write_text_atomic(path: PathLike, text: str) -> Path:
    """Write ``text`` to ``path`` atomically (a temporary file renamed into place)."""
    with atomic_open(path) as f:
        f.write(text)
    return Path(path)


def write_bytes_atomic(path: PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (a temporary file renamed into place), creating its folder."""
    try:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise SpaceIdInputError(f"{path}: cannot write: cannot create its folder ({exc.strerror})") from exc
    with atomic_open(path, binary=True) as f:
        f.write(data)
    return Path(path)


def write_csv_atomic(path: PathLike, rows: list[dict[str, Any]]) -> Path:
    """Write dict rows (columns: the first row's keys) as CSV to ``path`` atomically."""
    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=list(rows[0]), lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return write_text_atomic(path, text.getvalue())


def write_json_atomic(path: PathLike, data: dict[str, Any]) -> Path:
    """Write ``data`` as indented JSON to ``path`` atomically (numpy arrays and scalars become lists and numbers, NaN null)."""
    return write_text_atomic(path, json.dumps(json_value(data, "", nonfinite_as_null=True), indent=2) + "\n")


# ---------------------------------------------------------------------- JSON values
def json_value(value: Any, where: str, nonfinite_as_null: bool = False) -> Any:
    """``value`` with numpy arrays/scalars (and tuples, paths) turned into plain JSON types.

    A non-finite float is an error, or ``None`` with ``nonfinite_as_null`` (a figure that does not exist).
    """
    if isinstance(value, np.ndarray):
        return json_value(value.tolist(), where, nonfinite_as_null)
    if isinstance(value, np.generic):
        return json_value(value.item(), where, nonfinite_as_null)
    if value is None or isinstance(value, (bool, int, str)):
        return value
    if isinstance(value, float):
        if not math.isfinite(value):
            if nonfinite_as_null:
                return None
            raise SpaceIdInputError(f"truth{where}: {value!r} cannot be written to JSON; expected a finite number")
        return value
    if isinstance(value, dict):
        out = {}
        for key, item in value.items():
            if not isinstance(key, str):
                raise SpaceIdInputError(f"truth{where}: key {key!r} must be a string")
            out[str(key)] = json_value(item, f"{where}[{str(key)!r}]", nonfinite_as_null)
        return out
    if isinstance(value, (list, tuple)):
        return [json_value(item, f"{where}[{i}]", nonfinite_as_null) for i, item in enumerate(value)]
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    raise SpaceIdInputError(f"truth{where}: cannot write a {type(value).__name__} to JSON")


def jsonable(value: Any) -> Any:
    """Nested dicts, lists, tuples, named tuples, numpy arrays and scalars as JSON types; non-finite floats become
    ``None``, dict keys strings; other values are returned as they are."""
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist())
    if isinstance(value, np.generic):
        return jsonable(value.item())
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if hasattr(value, "_asdict"):  # NamedTuple
        return jsonable(value._asdict())
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value
