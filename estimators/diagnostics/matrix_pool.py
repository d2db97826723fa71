"""Several runs of the variation matrix read back and pooled into one table.

A cell of the matrix (an effect at one value of one axis) holds a few logs per run; the targets ask for a share of
right verdicts per cell, which a handful of logs cannot show. Runs made in pieces (other seeds, other machines,
other pinned axes) are pooled here: ``spaceid pool-matrix RUN [RUN ...] --out DIR`` reads each run's ``matrix.csv``
and ``summary.json`` (as ``spaceid diagnose-suite --matrix`` writes them), checks that they can be pooled (each a
matrix run, the same log length, no log twice, the same code unless told otherwise) and writes the pooled
``matrix.csv``, ``matrix.md`` and ``summary.json`` (:func:`~estimators.diagnostics.matrix.write_matrix`), each row
naming its run.
"""

from __future__ import annotations

import csv
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.variations import AXES

#: the columns a matrix run's CSV holds as text (every other column is a number, the booleans aside)
TEXT_COLUMNS = frozenset(
    {
        "effect",
        "robot",
        "attitude",
        "excitation",
        "slosh_model",
        "nearest_rival",
        "verdict",
        "runner_up",
        "rivals",
        "error",
        "run",
    }
)
INTEGER_COLUMNS = frozenset({"seed", "rate_hz"})
BOOLEAN_COLUMNS = frozenset({"correct"})

#: the columns the pooled summary needs (:func:`~estimators.diagnostics.matrix.summarise_matrix`; it reads
#: ``separation_power`` and ``rivals`` where a run has them)
REQUIRED_COLUMNS = (
    "effect",
    "seed",
    *AXES,
    "expected_power",
    "verdict",
    "correct",
    "rms_over_noise_after",
    *(f"z_{name}_after" for name in ("mdf", "bx", "by", "bz")),
    "wall_time_s",
)


@dataclass(frozen=True)
class MatrixRun:
    """One run of the variation matrix as written: ``rows`` typed as the run made them, ``info`` from its
    ``summary.json``, ``path`` its folder."""

    path: Path
    rows: list[dict[str, Any]]
    info: dict[str, Any]


def read_matrix_run(path: str | Path) -> MatrixRun:
    """The run written to folder ``path`` by ``spaceid diagnose-suite --matrix``.

    Raises:
        SpaceIdInputError: a file missing or unreadable, not a matrix run, a column missing or a cell that is not
            what its column holds (named by file, line and column)."""
    path = Path(path)
    csv_path, json_path = path / "matrix.csv", path / "summary.json"
    for needed in (csv_path, json_path):
        if not needed.is_file():
            raise SpaceIdInputError(f"{needed}: not found (a run folder of 'spaceid diagnose-suite --matrix' holds it)")
    try:
        info = json.loads(json_path.read_text())["info"]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise SpaceIdInputError(f"{json_path}: expected the JSON of a matrix run with an 'info' object ({exc})") from None
    if not isinstance(info, dict) or info.get("matrix") is not True:
        raise SpaceIdInputError(f"{json_path}: not a variation matrix run (info.matrix is not true)")
    try:
        with csv_path.open(newline="") as f:
            reader = csv.DictReader(f)
            columns = list(reader.fieldnames or [])
            missing = [c for c in REQUIRED_COLUMNS if c not in columns]
            if missing:
                raise SpaceIdInputError(f"{csv_path}: columns {', '.join(missing)} missing")
            rows = [
                {column: _cell(value, column, csv_path, line) for column, value in raw.items()}
                for line, raw in enumerate(reader, start=2)
            ]
    except (OSError, csv.Error, UnicodeDecodeError) as exc:
        raise SpaceIdInputError(f"{csv_path}: unreadable as CSV ({exc})") from None
    if not rows:
        raise SpaceIdInputError(f"{csv_path}: no logs")
    return MatrixRun(path, rows, info)


def _cell(value: str | None, column: str | None, path: Path, line: int) -> Any:
    """A CSV cell as the run wrote it: text, an integer, a boolean or a number (NaN as 'nan'); an empty cell
    ``None``."""
    if column is None or value is None:
        raise SpaceIdInputError(f"{path}, line {line}: expected as many cells as columns")
    if value == "":
        return None
    if column in TEXT_COLUMNS:
        return value
    if column in BOOLEAN_COLUMNS:
        if value not in ("True", "False"):
            raise SpaceIdInputError(f"{path}, line {line}, column {column}: expected True or False, got {value!r}")
        return value == "True"
    try:
        return int(value) if column in INTEGER_COLUMNS else float(value)
    except ValueError:
        kind = "an integer" if column in INTEGER_COLUMNS else "a number"
        raise SpaceIdInputError(f"{path}, line {line}, column {column}: expected {kind}, got {value!r}") from None


def pool_matrix_runs(runs: list[MatrixRun], mixed_code: bool = False) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """The rows of ``runs`` pooled (each with a ``run`` column: its folder's name) and the pooled run's ``info``: every
    run's seeds, effects, pinned axes and code (``runs``), the log length, the code versions and the wall time summed.

    Raises:
        SpaceIdInputError: fewer than one run, runs of different log lengths, a log (effect, seed, pinned axes) in two
            runs, or runs made by different code (``code_version``) without ``mixed_code``."""
    if not runs:
        raise SpaceIdInputError("pool-matrix: expected at least one run")
    durations = {run.info.get("duration_s") for run in runs}
    if len(durations) != 1:
        raise SpaceIdInputError(
            "pool-matrix: the runs' logs differ in length: "
            + ", ".join(f"{run.path} {run.info.get('duration_s')} s" for run in runs)
        )
    versions = list(dict.fromkeys(str(run.info.get("code_version", "unknown")) for run in runs))
    if len(versions) > 1 and not mixed_code:
        raise SpaceIdInputError(
            f"pool-matrix: the runs were made by different code ({', '.join(versions)}); pool them only if the "
            "diagnosis did not change between those versions, with --mixed-code"
        )
    seen: dict[tuple[str, int, str], Path] = {}
    rows: list[dict[str, Any]] = []
    for run in runs:
        fixed = json.dumps(run.info.get("fixed", {}), sort_keys=True)
        for row in run.rows:
            key = (str(row["effect"]), int(row["seed"]), fixed)
            if key in seen:
                raise SpaceIdInputError(
                    f"pool-matrix: the {key[0]} log of seed {key[1]} (pinned {fixed}) is in both {seen[key]} and {run.path}"
                )
            seen[key] = run.path
            rows.append({**row, "run": run.path.name})
    wall = [run.info.get("wall_time_s") for run in runs]
    info = {
        "matrix": True,
        "pooled": True,
        "duration_s": durations.pop(),
        "code_version": versions[0] if len(versions) == 1 else "mixed: " + ", ".join(versions),
        "runs": [
            {key: run.info.get(key) for key in ("first_seed", "seeds", "effects", "fixed", "code_version", "executor")}
            | {"path": str(run.path)}
            for run in runs
        ],
        "wall_time_s": math.fsum(w for w in wall if isinstance(w, int | float)),
    }
    return rows, info
