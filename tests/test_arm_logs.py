"""ArmLog (validation, CSV round trip) and the real UR5 log loader (all 9 movements, synthetic broken files)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from spaceid_gym.arm import ArmLog, list_movements, load_arm, load_ur5_movement
from spaceid_gym.errors import SpaceIdInputError

UR5_REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "ur5-real"
needs_real_logs = pytest.mark.skipif(not UR5_REAL.is_dir(), reason=f"real UR5 logs not found at {UR5_REAL}")


def _log(rng: np.random.Generator, T: int = 20, n: int = 3, ddq: bool = True, kind: str = "torque_Nm") -> ArmLog:
    return ArmLog(
        t_s=np.cumsum(rng.uniform(0.007, 0.009, T)),
        q_rad=rng.normal(size=(T, n)),
        dq_rad_s=rng.normal(size=(T, n)),
        ddq_rad_s2=rng.normal(size=(T, n)) if ddq else None,
        effort=rng.normal(size=(T, n)),
        effort_kind=kind,
        name="synthetic",
    )


# ---------------------------------------------------------------------------------------- ArmLog
@pytest.mark.parametrize(("ddq", "kind", "effort_column"), [(True, "torque_Nm", "tau1"), (False, "current_A", "i1")])
def test_arm_log_csv_round_trip_is_bit_exact(tmp_path, ddq, kind, effort_column) -> None:
    log = _log(np.random.default_rng(0), ddq=ddq, kind=kind)
    path = log.to_csv(tmp_path / "run.csv")
    header = path.read_text().splitlines()[0].split(",")
    assert header[:4] == ["t", "q1", "q2", "q3"] and effort_column in header and ("ddq1" in header) == ddq
    back = ArmLog.from_csv(path, n_joints=3)
    assert back.name == "run" and back.effort_kind == kind
    np.testing.assert_array_equal(back.table(), log.table())
    assert (back.ddq_rad_s2 is None) == (not ddq)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.csv"]  # no temporary file left


def test_arm_log_validation_names_column_and_sample() -> None:
    rng = np.random.default_rng(1)
    log = _log(rng)
    dq = log.dq_rad_s.copy()
    dq[4, 1] = np.nan
    with pytest.raises(SpaceIdInputError, match=r"column 'dq2' has the non-finite value nan at sample index 4"):
        ArmLog(log.t_s, log.q_rad, dq, None, log.effort, name="x")
    t = log.t_s.copy()
    t[6] = t[5]
    with pytest.raises(SpaceIdInputError, match=r"'t' must be strictly increasing, but sample index 6"):
        ArmLog(t, log.q_rad, log.dq_rad_s, None, log.effort)
    with pytest.raises(SpaceIdInputError, match="effort_kind must be one of"):
        ArmLog(log.t_s, log.q_rad, log.dq_rad_s, None, log.effort, effort_kind="torque")
    with pytest.raises(SpaceIdInputError, match=r"effort must have shape \(20, 3\)"):
        ArmLog(log.t_s, log.q_rad, log.dq_rad_s, None, log.effort[:, :2])


def test_arm_log_select_keeps_rows_together() -> None:
    log = _log(np.random.default_rng(2))
    part = log.select(slice(3, 12, 2))
    np.testing.assert_array_equal(part.table(), log.table()[3:12:2])


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda lines: ["q1,t", *lines[1:]], r"header must start 't,q1'"),
        (lambda lines: [lines[0].replace("tau2", "tau9"), *lines[1:]], r"column 12 is 'tau9', expected 'tau2'"),
        (
            lambda lines: [*lines[:3], lines[3].replace(lines[3].split(",")[2], "abc", 1), *lines[4:]],
            r"line 4, column 'q2': 'abc' is not a number",
        ),
        (lambda lines: [*lines[:5], lines[5] + ",1", *lines[6:]], r"line 6: 14 values, expected 13"),
        (lambda lines: lines[1:], "missing header"),
    ],
)
def test_arm_log_from_csv_errors_name_file_line_and_column(tmp_path, edit, message) -> None:
    path = _log(np.random.default_rng(3)).to_csv(tmp_path / "log.csv")
    path.write_text("\n".join(edit(path.read_text().splitlines())) + "\n")
    with pytest.raises(SpaceIdInputError, match=message) as info:
        ArmLog.from_csv(path)
    assert str(path) in str(info.value)


# ---------------------------------------------------------------------------------------- real logs
@needs_real_logs
def test_all_real_movements_load_and_report_what_was_dropped() -> None:
    movements = list_movements(UR5_REAL)
    assert len(movements) == 9
    robot = load_arm("ur5")
    for movement in movements:
        folder = UR5_REAL / movement
        log, report = load_ur5_movement(folder)
        assert log.n_joints == 6 and log.effort_kind == "current_A" and log.ddq_rad_s2 is None and log.name == movement
        assert report.n_samples == log.n_samples > 1000
        assert report.max_time_offset_s < 1e-4  # the files' time stamps agree within 0.1 ms
        assert movement in report.describe()
        for name, file_report in report.files.items():
            raw = (folder / f"{name}.csv").read_bytes()
            n_lines = len(raw.decode().splitlines())
            assert (file_report.truncated_line is not None) == (not raw.endswith(b"\n")), (movement, name)
            assert file_report.rows_kept == log.n_samples
            assert file_report.rows_dropped == n_lines - log.n_samples
            assert name in file_report.describe()
        # time is q_actual's (first column), rows of different files are aligned: the finite
        # difference of q agrees with the mean rate better than with a rate shifted by one row
        q_file = np.loadtxt(folder / "q_actual.csv", delimiter=",", max_rows=log.n_samples)
        np.testing.assert_array_equal(log.t_s, q_file[:, 0])
        rate = np.diff(log.q_rad, axis=0) / np.diff(log.t_s)[:, None]
        mid = 0.5 * (log.dq_rad_s[:-1] + log.dq_rad_s[1:])
        aligned = np.sqrt(np.mean((rate - mid) ** 2))
        assert aligned < np.sqrt(np.mean((rate[1:] - mid[:-1]) ** 2)) and aligned < np.sqrt(np.mean((rate[:-1] - mid[1:]) ** 2))
        assert robot.n_joints == log.n_joints


@needs_real_logs
def test_real_logs_known_defects_are_reported() -> None:
    _, report = load_ur5_movement(UR5_REAL / "Movement_No4_Acc")
    q_report = report.files["q_actual"]
    assert q_report.truncated_line is not None and q_report.truncated_line[0] == 2857
    assert q_report.unmatched_end == 22 and q_report.unmatched_start == q_report.unmatched_inside == 0
    assert report.period_median_s == pytest.approx(0.008, abs=1e-9) and report.n_gaps == 0
    _, report = load_ur5_movement(UR5_REAL / "Movement_No1")
    assert report.period_min_s < 0.0075 and report.period_max_s > 0.024 and report.n_gaps > 1000  # jitter and missing samples
    assert report.period_mean_s > 1.5 * report.period_median_s


@needs_real_logs
def test_ur5_model_gravity_matches_the_controllers_model_at_rest() -> None:
    """An independent reference: the controller's own model torque (m_target) where the arm is at rest."""
    robot = load_arm("ur5")
    data = robot.create_data()
    for movement in ("Movement_No4_Acc", "Movement_No8_Singularity_Free_1"):
        log, _ = load_ur5_movement(UR5_REAL / movement, effort="m_target")
        assert log.effort_kind == "torque_Nm"
        # at rest: every joint rate below 1e-4 rad/s for 11 samples (88 ms) around, so no acceleration either
        still = np.all(np.abs(log.dq_rad_s) < 1e-4, axis=1)
        at_rest = 5 + np.flatnonzero(np.lib.stride_tricks.sliding_window_view(still, 11).all(axis=1))
        assert at_rest.size >= 100
        for i in at_rest[:: at_rest.size // 10]:
            tau = pin.rnea(robot.model, data, log.q_rad[i], np.zeros(6), np.zeros(6))
            # shoulder and elbow carry the weight: within 6 % + 0.3 N m of UR's model
            np.testing.assert_allclose(tau[1:3], log.effort[i, 1:3], rtol=0.06, atol=0.3)


# ---------------------------------------------------------------------------------------- synthetic movements
def _rows(t: np.ndarray, values: np.ndarray) -> list[str]:
    return [", ".join(f"{x:.6f}" for x in (ti, *row)) for ti, row in zip(t, values, strict=True)]


def _movement(
    tmp_path: Path, T: int = 50, offsets_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
) -> tuple[Path, dict[str, list[str]]]:
    """A clean movement folder; returns it and each file's lines (to break before writing again)."""
    rng = np.random.default_rng(4)
    folder = tmp_path / "Movement_Test"
    folder.mkdir()
    t = 0.1 + 0.008 * np.arange(T)
    lines = {}
    for name, offset in zip(("q_actual", "qd_actual", "i_actual"), offsets_s, strict=True):
        lines[name] = _rows(t + offset, rng.normal(size=(T, 6)))
        _write(folder, name, lines[name])
    return folder, lines


def _write(folder: Path, name: str, lines: list[str], final_newline: bool = True) -> None:
    (folder / f"{name}.csv").write_text("\n".join(lines) + ("\n" if final_newline else ""))


def test_synthetic_clean_movement_with_offset_time_stamps(tmp_path) -> None:
    folder, lines = _movement(tmp_path, offsets_s=(0.0, 3e-5, -4e-5))
    log, report = load_ur5_movement(folder)
    assert log.n_samples == 50 and all(r.rows_dropped == 0 for r in report.files.values())
    assert report.max_time_offset_s == pytest.approx(4e-5, abs=2e-6)
    np.testing.assert_allclose(log.effort[7], [float(x) for x in lines["i_actual"][7].split(",")[1:]])


def test_truncated_last_lines_are_dropped_and_reported(tmp_path) -> None:
    folder, lines = _movement(tmp_path)
    _write(folder, "q_actual", [*lines["q_actual"][:-1], lines["q_actual"][-1][:30]], final_newline=False)  # cut in a number
    _write(folder, "qd_actual", lines["qd_actual"], final_newline=False)  # parses, but unterminated
    _write(folder, "i_actual", [*lines["i_actual"][:-1], lines["i_actual"][-1][:12]])  # too few values, with newline
    log, report = load_ur5_movement(folder)
    assert log.n_samples == 49
    for name in ("q_actual", "qd_actual", "i_actual"):
        assert report.files[name].truncated_line[0] == 50
        assert report.files[name].rows_dropped == 1
    assert "truncated last line 50" in report.describe()


def test_mismatched_rows_keep_common_time_stamps(tmp_path) -> None:
    folder, lines = _movement(tmp_path)
    _write(folder, "qd_actual", lines["qd_actual"][:45])  # 5 rows short at the end
    _write(folder, "i_actual", lines["i_actual"][2:20] + lines["i_actual"][21:])  # 2 missing at the start, 1 inside
    log, report = load_ur5_movement(folder)
    assert log.n_samples == 50 - 5 - 2 - 1
    q = report.files["q_actual"]
    assert (q.unmatched_start, q.unmatched_end, q.unmatched_inside) == (2, 5, 1)
    assert report.files["qd_actual"].unmatched_start == 2 and report.files["i_actual"].unmatched_end == 5
    assert report.n_gaps == 1  # the missing sample inside


def test_nan_duplicate_and_backwards_rows_are_dropped(tmp_path) -> None:
    folder, lines = _movement(tmp_path)
    q = list(lines["q_actual"])
    q[10] = q[10].replace(q[10].split(",")[3], " nan", 1)
    q[20] = q[19]  # duplicate time (line 21)
    q[30] = q[5]  # time going back (line 31)
    _write(folder, "q_actual", q)
    log, report = load_ur5_movement(folder)
    r = report.files["q_actual"]
    assert (r.nan_lines, r.duplicate_time_lines, r.backwards_time_lines) == ([11], [21], [31])
    assert log.n_samples == 47 and np.isfinite(log.q_rad).all()
    assert "1 NaN (lines 11)" in r.describe()


def test_garbage_inside_a_file_raises_naming_file_and_line(tmp_path) -> None:
    folder, lines = _movement(tmp_path)
    _write(folder, "qd_actual", [*lines["qd_actual"][:7], "this is not data", *lines["qd_actual"][8:]])
    with pytest.raises(SpaceIdInputError, match=r"qd_actual.csv, line 8: 1 values, expected 7"):
        load_ur5_movement(folder)
    _write(
        folder,
        "qd_actual",
        [*lines["qd_actual"][:7], lines["qd_actual"][7].replace(",", ", abc,", 1)[:-1], *lines["qd_actual"][8:]],
    )
    with pytest.raises(SpaceIdInputError, match=r"qd_actual.csv, line 8: 8 values"):
        load_ur5_movement(folder)
    _write(folder, "qd_actual", [*lines["qd_actual"][:7], "0.1, 1, 2, x, 4, 5, 6", *lines["qd_actual"][8:]])
    with pytest.raises(SpaceIdInputError, match=r"qd_actual.csv, line 8: 'x' is not a number"):
        load_ur5_movement(folder)


def test_short_empty_and_missing_files_raise(tmp_path) -> None:
    folder, lines = _movement(tmp_path)
    _write(folder, "i_actual", lines["i_actual"][:1])
    with pytest.raises(SpaceIdInputError, match=r"i_actual.csv: only 1 valid row"):
        load_ur5_movement(folder)
    (folder / "i_actual.csv").write_text("")
    with pytest.raises(SpaceIdInputError, match=r"i_actual.csv: file is empty"):
        load_ur5_movement(folder)
    (folder / "i_actual.csv").unlink()
    with pytest.raises(SpaceIdInputError, match=r"i_actual.csv: file not found"):
        load_ur5_movement(folder)
    with pytest.raises(SpaceIdInputError, match="effort must be one of"):
        load_ur5_movement(folder, effort="current")
    with pytest.raises(SpaceIdInputError, match="no such movement folder"):
        load_ur5_movement(tmp_path / "nowhere")
    with pytest.raises(SpaceIdInputError, match="no such folder"):
        list_movements(tmp_path / "nowhere")
    assert list_movements(tmp_path) == ["Movement_Test"]


def test_files_without_common_time_stamps_raise(tmp_path) -> None:
    folder, lines = _movement(tmp_path)
    _write(
        folder, "i_actual", [line.replace(line.split(",")[0], f"{100 + i:.6f}", 1) for i, line in enumerate(lines["i_actual"])]
    )
    with pytest.raises(SpaceIdInputError, match="share 0 time stamps"):
        load_ur5_movement(folder)
