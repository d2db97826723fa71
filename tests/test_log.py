"""Tests for :mod:`spaceid_gym.log`: CSV round trip, validation messages, atomic writes, datasets."""

from __future__ import annotations

import json
import re
from contextlib import AbstractContextManager
from pathlib import Path

import numpy as np
import pytest

import spaceid_gym.files as files_module
import spaceid_gym.log_format as log_format_module
from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.log import Dataset, MeasurementLog, load_dataset, write_dataset
from spaceid_gym.robots import load_robot

N_JOINTS = 3
URDF_TEXT = load_robot("quick3").urdf_text  # 3 joints, as N_JOINTS


def make_log(n_samples: int = 50, n_joints: int = N_JOINTS, with_quat: bool = True, seed: int = 0) -> MeasurementLog:
    rng = np.random.default_rng(seed)
    t = 0.1 * np.arange(n_samples) + rng.uniform(0.0, 1e-3, n_samples)
    quat = rng.normal(size=(n_samples, 4))
    quat /= np.linalg.norm(quat, axis=1, keepdims=True)
    return MeasurementLog(
        t_s=t,
        q_rad=rng.normal(size=(n_samples, n_joints)) * np.pi,
        dq_rad_s=rng.normal(size=(n_samples, n_joints)) * 1e-3,
        omega_base_body_rad_s=rng.normal(size=(n_samples, 3)) * 1e-7,
        quat_base_to_inertial_wxyz=quat if with_quat else None,
    )


def assert_logs_identical(a: MeasurementLog, b: MeasurementLog) -> None:
    for name in ("t_s", "q_rad", "dq_rad_s", "omega_base_body_rad_s"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
        assert getattr(a, name).tobytes() == getattr(b, name).tobytes(), name  # bitwise, incl. -0.0
    if a.quat_base_to_inertial_wxyz is None:
        assert b.quat_base_to_inertial_wxyz is None
    else:
        assert b.quat_base_to_inertial_wxyz is not None
        assert a.quat_base_to_inertial_wxyz.tobytes() == b.quat_base_to_inertial_wxyz.tobytes()


HEADER = "t,q1,q2,dq1,dq2,wx,wy,wz"
ROW1 = "0.0,0.1,0.2,0.01,0.02,0.001,0.002,0.003"
ROW2 = "0.5,0.1,0.2,0.01,0.02,0.001,0.002,0.003"
ROW3 = "1.0,0.1,0.2,0.01,0.02,0.001,0.002,0.003"


def write(tmp_path: Path, text: str, name: str = "log.csv") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def raises_naming(path: Path, pattern: str) -> AbstractContextManager[pytest.ExceptionInfo[SpaceIdInputError]]:
    """``pytest.raises`` for a SpaceIdInputError whose message names ``path`` and matches ``pattern``."""
    return pytest.raises(SpaceIdInputError, match=re.escape(str(path)) + r".*" + pattern)


# ---------------------------------------------------------------------- MeasurementLog basics
def test_properties_and_window() -> None:
    log = make_log(n_samples=50, with_quat=False)
    assert log.n_joints == N_JOINTS
    assert log.n_samples == len(log) == 50
    assert log.duration_s == pytest.approx(log.t_s[-1] - log.t_s[0])
    assert log.sample_period_s == pytest.approx(0.1, abs=2e-3)
    assert "n_samples=50" in repr(log)

    t0, t1 = float(log.t_s[10]), float(log.t_s[20])
    win = log.window(t0, t1)
    assert len(win) == 10  # t0 included, t1 excluded
    np.testing.assert_array_equal(win.t_s, log.t_s[10:20])
    np.testing.assert_array_equal(win.q_rad, log.q_rad[10:20])
    np.testing.assert_array_equal(win.dq_rad_s, log.dq_rad_s[10:20])
    np.testing.assert_array_equal(win.omega_base_body_rad_s, log.omega_base_body_rad_s[10:20])
    assert win.quat_base_to_inertial_wxyz is None
    win_q = make_log(with_quat=True).window(0.0, 0.35)
    assert win_q.quat_base_to_inertial_wxyz is not None and win_q.quat_base_to_inertial_wxyz.shape == (4, 4)

    with pytest.raises(SpaceIdInputError, match="holds 0 samples"):
        log.window(100.0, 200.0)
    with pytest.raises(SpaceIdInputError, match="must be greater than t_start_s"):
        log.window(2.0, 1.0)


def test_arrays_are_read_only_copies() -> None:
    t = np.array([0.0, 1.0, 2.0])
    log = MeasurementLog(t, np.zeros((3, 1)), np.zeros((3, 1)), np.zeros((3, 3)))
    t[0] = -5.0
    assert log.t_s[0] == 0.0
    with pytest.raises(ValueError):
        log.t_s[0] = 1.0
    assert log.validate("x") is log


def test_constructor_validates() -> None:
    z = np.zeros
    with pytest.raises(SpaceIdInputError, match=r"dq_rad_s must have shape \(3, 2\)"):
        MeasurementLog([0.0, 1.0, 2.0], z((3, 2)), z((3, 3)), z((3, 3)))
    with pytest.raises(SpaceIdInputError, match=r"quat_base_to_inertial_wxyz must have shape \(3, 4\)"):
        MeasurementLog([0.0, 1.0, 2.0], z((3, 2)), z((3, 2)), z((3, 3)), z((3, 3)))
    q = z((3, 2))
    q[1, 1] = np.nan
    with pytest.raises(SpaceIdInputError, match=r"column 'q2' \(q_rad\[:, 1\]\) .*nan at sample index 1"):
        MeasurementLog([0.0, 1.0, 2.0], q, z((3, 2)), z((3, 3)))
    with pytest.raises(SpaceIdInputError, match=r"'t' must be strictly increasing, but sample index 2"):
        MeasurementLog([0.0, 1.0, 1.0], z((3, 2)), z((3, 2)), z((3, 3)))
    with pytest.raises(SpaceIdInputError, match="at least 1 sample"):
        MeasurementLog(np.zeros(0), z((0, 2)), z((0, 2)), z((0, 3)))
    single = MeasurementLog([0.0], z((1, 2)), z((1, 2)), z((1, 3)))
    with pytest.raises(SpaceIdInputError, match="sample period needs at least 2 samples"):
        _ = single.sample_period_s


# ---------------------------------------------------------------------- CSV round trip
@pytest.mark.parametrize("with_quat", [True, False])
def test_csv_round_trip_is_bit_exact(tmp_path: Path, with_quat: bool) -> None:
    log = make_log(with_quat=with_quat)
    # awkward values: negative zero, subnormal, huge, many digits
    q = log.q_rad.copy()
    q[0, :3] = [-0.0, 5e-324, 1.2345678901234567e300]
    log = MeasurementLog(log.t_s, q, log.dq_rad_s, log.omega_base_body_rad_s, log.quat_base_to_inertial_wxyz)
    path = log.to_csv(tmp_path / "log.csv")
    header = path.read_text().splitlines()[0]
    expected = "t,q1,q2,q3,dq1,dq2,dq3,wx,wy,wz" + (",qw,qx,qy,qz" if with_quat else "")
    assert header == expected
    back = MeasurementLog.from_csv(path, n_joints=N_JOINTS)
    assert_logs_identical(log, back)
    assert [p.name for p in tmp_path.iterdir()] == ["log.csv"]


def test_csv_reader_tolerates_spaces_blank_lines_and_bom(tmp_path: Path) -> None:
    path = write(tmp_path, "\ufeff t, q1, q2, dq1, dq2, wx, wy, wz\r\n" + ROW1 + "\r\n\r\n" + ROW2 + "\n\n")
    log = MeasurementLog.from_csv(path)
    assert log.n_joints == 2 and log.n_samples == 2


# ---------------------------------------------------------------------- CSV errors
def test_missing_file(tmp_path: Path) -> None:
    path = tmp_path / "log.csv"
    with raises_naming(path, "file not found"):
        MeasurementLog.from_csv(path)


@pytest.mark.parametrize("text", ["", "\n\n  \n"])
def test_empty_file(tmp_path: Path, text: str) -> None:
    path = write(tmp_path, text)
    with raises_naming(path, "file is empty"):
        MeasurementLog.from_csv(path)


def test_missing_header(tmp_path: Path) -> None:
    path = write(tmp_path, ROW1 + "\n" + ROW2 + "\n")
    with raises_naming(path, "missing header; file line 1 starts with the number '0.0'"):
        MeasurementLog.from_csv(path)


def test_header_only(tmp_path: Path) -> None:
    path = write(tmp_path, HEADER + "\n")
    with raises_naming(path, "no data rows after the header"):
        MeasurementLog.from_csv(path)
    path = write(tmp_path, HEADER + "\n" + ROW1 + "\n")
    assert MeasurementLog.from_csv(path).n_samples == 1


@pytest.mark.parametrize(
    ("header", "pattern"),
    [
        ("time,q1,q2,dq1,dq2,wx,wy,wz", "column 1 is 'time', expected 't'"),
        ("t,dq1,dq2,wx,wy,wz", "column 2 is 'dq1', expected 'q1'"),
        ("t,q1,q3,dq1,dq2,wx,wy,wz", "column 3 is 'q3', expected 'q2'"),
        ("t,q1,q2,dq2,dq1,wx,wy,wz", "column 4 is 'dq2', expected 'dq1'"),
        ("t,q1,q2,dq1,wx,wy,wz", r"column 5 is 'wx', expected 'dq2' \(2 joint-angle columns q1..q2 need 2"),
        ("t,q1,q2,q3,dq7,dq2,dq3,wx,wy,wz", "column 5 is 'dq7', expected 'dq1'"),
        ("t,q1,q2,dq1,dq2,wx,wy,omega_z", "column 8 is 'omega_z', expected 'wz'"),
        ("t,q1,q2,dq1,dq2,wx,wy", "column 8 is missing, expected 'wz'"),
        ("t,q1,q2,dq1,dq2,wx,wy,wz,qw,qx", "all four 'qw,qx,qy,qz' or none; found only 'qw,qx'"),
        ("t,q1,q2,dq1,dq2,wx,wy,wz,qx,qy,qz,qw", "column 9 is 'qx', expected 'qw'"),
        ("t,q1,q2,dq1,dq2,wx,wy,wz,qw,qx,qy,qz,extra", "unexpected column 13 'extra'"),
    ],
)
def test_bad_header(tmp_path: Path, header: str, pattern: str) -> None:
    n_cols = len(header.split(","))
    rows = "\n".join(",".join(["0.0"] * n_cols) for _ in range(2))
    path = write(tmp_path, header + "\n" + rows + "\n")
    with raises_naming(path, pattern):
        MeasurementLog.from_csv(path)


def test_joint_count_mismatch(tmp_path: Path) -> None:
    path = make_log(n_joints=3).to_csv(tmp_path / "log.csv")
    with pytest.raises(SpaceIdInputError, match=re.escape(f"{path} has 3 joints (q1..q3), the robot has 6")):
        MeasurementLog.from_csv(path, n_joints=6)


@pytest.mark.parametrize(
    ("cell", "pattern"),
    [
        ("abc", r"column 'dq1' \(column 4\), data row 2 \(file line 3\): 'abc' is not a number"),
        ("", r"column 'dq1' \(column 4\), data row 2 \(file line 3\): '' is not a number"),
        ("nan", r"column 'dq1' \(column 4\), data row 2 \(file line 3\): 'nan' is not a finite number"),
        ("-inf", r"column 'dq1' \(column 4\), data row 2 \(file line 3\): '-inf' is not a finite number"),
    ],
)
def test_bad_value(tmp_path: Path, cell: str, pattern: str) -> None:
    row2 = ROW2.split(",")
    row2[3] = cell
    path = write(tmp_path, "\n".join([HEADER, ROW1, ",".join(row2), ROW3]) + "\n")
    with raises_naming(path, pattern):
        MeasurementLog.from_csv(path)


def test_non_increasing_time(tmp_path: Path) -> None:
    path = write(tmp_path, "\n".join([HEADER, ROW1, ROW2, ROW2]) + "\n")
    with raises_naming(path, r"'t' must be strictly increasing, but data row 3 \(file line 4\) has t = 0.5 s"):
        MeasurementLog.from_csv(path)


def test_ragged_row(tmp_path: Path) -> None:
    path = write(tmp_path, "\n".join([HEADER, ROW1, ROW2 + ",7.0", ROW3]) + "\n")
    with raises_naming(path, r"data row 2 \(file line 3\) has 9 values, expected 8"):
        MeasurementLog.from_csv(path)
    path = write(tmp_path, "\n".join([HEADER, ROW1, ROW2, "1.0,0.1"]) + "\n")
    with raises_naming(path, r"data row 3 \(file line 4\) has 2 values, expected 8"):
        MeasurementLog.from_csv(path)


def test_not_utf8(tmp_path: Path) -> None:
    path = tmp_path / "log.csv"
    path.write_bytes(b"\x89PNG\r\n\x1a\n\x00\xff\xfe")
    with raises_naming(path, "not a UTF-8 text file"):
        MeasurementLog.from_csv(path)


# ---------------------------------------------------------------------- atomic writes
def test_failed_write_keeps_previous_file_and_leaves_no_temp(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = make_log(seed=1).to_csv(tmp_path / "log.csv")
    before = path.read_bytes()
    calls = 0
    real_format_row = log_format_module._format_row

    def failing_format_row(values: list[float]) -> str:
        nonlocal calls
        calls += 1
        if calls == 5:
            raise OSError("disk full")
        return real_format_row(values)

    monkeypatch.setattr(log_format_module, "_format_row", failing_format_row)
    with pytest.raises(OSError, match="disk full"):
        make_log(seed=2).to_csv(path)
    assert calls == 5  # the temp file was opened and partly written
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["log.csv"]


def test_failed_rename_leaves_no_temp(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def failing_replace(src: object, dst: object) -> None:
        raise OSError("rename failed")

    monkeypatch.setattr(files_module.os, "replace", failing_replace)
    with pytest.raises(OSError, match="rename failed"):
        make_log().to_csv(tmp_path / "log.csv")
    assert list(tmp_path.iterdir()) == []


def test_write_into_missing_directory(tmp_path: Path) -> None:
    path = tmp_path / "nope" / "log.csv"
    with raises_naming(path, "cannot write"):
        make_log().to_csv(path)


# ---------------------------------------------------------------------- datasets
def test_dataset_round_trip_with_numpy_truth(tmp_path: Path) -> None:
    log = make_log()
    truth = {
        "base_mass_kg": np.float64(123.25),
        "inertia_kgm2": np.diag([1.0, 2.0, 3.0]),
        "n_links": np.int64(4),
        "nested": {"flag": np.bool_(True), "values": (np.float32(0.5), 1.0 / 3.0)},
        "name": "sim",
    }
    directory = write_dataset(tmp_path / "a" / "b", log, URDF_TEXT, truth)
    assert sorted(p.name for p in directory.iterdir()) == ["log.csv", "robot.urdf", "truth.json"]
    text = (directory / "truth.json").read_text()
    assert text.startswith('{\n  "base_mass_kg": 123.25,')  # indent 2, sorted keys

    ds = load_dataset(directory, n_joints=N_JOINTS)
    assert isinstance(ds, Dataset)
    assert ds.path == directory
    assert ds.robot_urdf_path == directory / "robot.urdf"
    assert ds.robot_urdf_path.read_text() == URDF_TEXT
    assert_logs_identical(log, ds.log)
    assert ds.truth == {
        "base_mass_kg": 123.25,
        "inertia_kgm2": [[1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 3.0]],
        "n_links": 4,
        "nested": {"flag": True, "values": [0.5, 1.0 / 3.0]},
        "name": "sim",
    }

    # overwrite in place, now without truth: the stale truth.json goes away
    log2 = make_log(seed=3, with_quat=False)
    write_dataset(directory, log2, URDF_TEXT, None)
    ds2 = load_dataset(directory)
    assert ds2.truth is None
    assert_logs_identical(log2, ds2.log)


def test_dataset_without_truth(tmp_path: Path) -> None:
    directory = tmp_path / "real"
    directory.mkdir()
    make_log().to_csv(directory / "log.csv")
    (directory / "robot.urdf").write_text(URDF_TEXT)
    assert load_dataset(directory).truth is None


def test_truth_that_cannot_be_json(tmp_path: Path) -> None:
    with pytest.raises(SpaceIdInputError, match=r"truth\['a'\]\[1\]: nan cannot be written"):
        write_dataset(tmp_path / "d", make_log(), URDF_TEXT, {"a": np.array([1.0, np.nan])})
    with pytest.raises(SpaceIdInputError, match=r"truth: key 3 must be a string"):
        write_dataset(tmp_path / "d", make_log(), URDF_TEXT, {3: 1.0})
    assert not (tmp_path / "d").exists()  # nothing written


def test_load_dataset_errors(tmp_path: Path) -> None:
    missing = tmp_path / "missing"
    with raises_naming(missing, "dataset folder not found"):
        load_dataset(missing)

    directory = tmp_path / "ds"
    directory.mkdir()
    with raises_naming(directory / "log.csv", "file not found"):
        load_dataset(directory)
    make_log().to_csv(directory / "log.csv")
    with raises_naming(directory / "robot.urdf", "file not found"):
        load_dataset(directory)
    (directory / "robot.urdf").write_text(URDF_TEXT)

    (directory / "truth.json").write_text('{"mass": 1.0,')
    with raises_naming(directory / "truth.json", "invalid JSON: Expecting property name"):
        load_dataset(directory)
    (directory / "truth.json").write_text(json.dumps([1, 2]))
    with raises_naming(directory / "truth.json", "expected a JSON object"):
        load_dataset(directory)

    (directory / "truth.json").unlink()
    with raises_naming(directory / "log.csv", "has 3 joints"):
        load_dataset(directory, n_joints=6)
    (directory / "robot.urdf").write_text(load_robot("paper6").urdf_text)
    with raises_naming(directory / "log.csv", "has 3 joints .* the robot has 6"):
        load_dataset(directory)  # the joint count comes from robot.urdf


def test_quaternion_must_be_unit() -> None:
    log = make_log(n_samples=4)
    quat = np.array(log.quat_base_to_inertial_wxyz)
    quat[2] *= 2.0
    with pytest.raises(SpaceIdInputError, match=r"'qw,qx,qy,qz' at sample index 2 .*have norm 2.0; expected a unit quaternion"):
        MeasurementLog(log.t_s, log.q_rad, log.dq_rad_s, log.omega_base_body_rad_s, quat)
