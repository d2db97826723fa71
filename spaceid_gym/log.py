"""Measurement logs of a free-floating robot and the dataset folder that holds them.

A :class:`MeasurementLog` is one window of measurements of a robot with ``n`` arm joints: time,
joint angles and rates, the base angular velocity in the base body frame (what a gyro measures)
and, optionally, the base attitude. It is stored as a CSV file with the header

    t,q1,...,qN,dq1,...,dqN,wx,wy,wz[,qw,qx,qy,qz]

(SI units: s, rad, rad/s; the quaternion is scalar first, base-to-inertial). Values are written
with ``repr`` so a write/read round trip is bit exact. Reading, writing and checking that file:
:mod:`spaceid_gym.log_format`.

A dataset folder holds ``log.csv``, ``robot.urdf`` and, for simulated data, ``truth.json``
(:func:`write_dataset`, :func:`load_dataset`). Every file is written atomically (:mod:`spaceid_gym.files`:
temporary file in the same directory, then ``os.replace``), so a failure never leaves a half-written file.

Every input problem raises :class:`~spaceid_gym.errors.SpaceIdInputError` naming the file, the
column and the row.
"""

from __future__ import annotations

import json
from contextlib import suppress
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from spaceid_gym.arrays import FloatArray
from spaceid_gym.errors import SpaceIdInputError

# the atomic writes live in spaceid_gym.files; re-exported here for code written against their first home
from spaceid_gym.files import PathLike as PathLike
from spaceid_gym.files import atomic_open as atomic_open
from spaceid_gym.files import json_value
from spaceid_gym.files import write_bytes_atomic as write_bytes_atomic
from spaceid_gym.files import write_csv_atomic as write_csv_atomic
from spaceid_gym.files import write_json_atomic as write_json_atomic
from spaceid_gym.files import write_text_atomic as write_text_atomic
from spaceid_gym.log_format import check_log_arrays, log_table, read_log_csv, sample_index_label, write_log_csv
from spaceid_gym.robots import load_robot

LOG_FILENAME = "log.csv"
URDF_FILENAME = "robot.urdf"
TRUTH_FILENAME = "truth.json"


class JointTimeSeries:
    """What every log of joint measurements has: sample times ``t_s`` (T,) and joint angles ``q_rad`` (T, n).

    Shared by :class:`MeasurementLog` and :class:`spaceid_gym.arm.joint_log.ArmLog` (frozen dataclasses).
    """

    t_s: FloatArray
    q_rad: FloatArray

    def _freeze_arrays(self, fields: tuple[str, ...], optional: tuple[str, ...], source: str) -> None:
        """Replace each field by a read-only float64 copy (``optional`` ones may be ``None``)."""
        for name in fields:
            value = getattr(self, name)
            if value is None and name in optional:
                continue
            try:
                array = np.array(value, dtype=np.float64)
            except (TypeError, ValueError) as exc:
                raise SpaceIdInputError(f"{source}: {name} must be an array of numbers ({exc})") from exc
            array.flags.writeable = False
            object.__setattr__(self, name, array)

    @property
    def n_joints(self) -> int:
        """Number of joints ``n``."""
        return int(self.q_rad.shape[1])

    @property
    def n_samples(self) -> int:
        """Number of samples ``T``."""
        return int(self.t_s.shape[0])

    @property
    def duration_s(self) -> float:
        """``t[-1] - t[0]``, s."""
        return float(self.t_s[-1] - self.t_s[0])

    @property
    def sample_period_s(self) -> float:
        """Median time step, s (needs at least 2 samples)."""
        if self.n_samples < 2:
            raise SpaceIdInputError(f"{self!r}: the sample period needs at least 2 samples")
        return float(np.median(np.diff(self.t_s)))

    def __len__(self) -> int:
        return self.n_samples


@dataclass(frozen=True, eq=False, repr=False)
class MeasurementLog(JointTimeSeries):
    """One window of measurements of a free-floating robot with ``n`` arm joints.

    The constructor copies the arrays to read-only float64 arrays and validates them (shapes,
    finite values, strictly increasing time), raising :class:`SpaceIdInputError` otherwise.

    Attributes:
        t_s: time, shape (T,), s, strictly increasing, T >= 1.
        q_rad: joint angles, shape (T, n), rad.
        dq_rad_s: joint rates, shape (T, n), rad/s.
        omega_base_body_rad_s: base angular velocity in the base body frame, shape (T, 3), rad/s.
        quat_base_to_inertial_wxyz: base attitude, shape (T, 4), unit quaternion ``(w, x, y, z)``
            rotating base-frame vectors into the inertial frame; ``None`` if not measured.
    """

    t_s: FloatArray
    q_rad: FloatArray
    dq_rad_s: FloatArray
    omega_base_body_rad_s: FloatArray
    quat_base_to_inertial_wxyz: FloatArray | None = None

    def __post_init__(self) -> None:
        fields = ("t_s", "q_rad", "dq_rad_s", "omega_base_body_rad_s", "quat_base_to_inertial_wxyz")
        self._freeze_arrays(fields, ("quat_base_to_inertial_wxyz",), "MeasurementLog")
        self.validate("MeasurementLog")

    def __repr__(self) -> str:
        quat = "yes" if self.quat_base_to_inertial_wxyz is not None else "no"
        return (
            f"MeasurementLog(n_samples={self.n_samples}, n_joints={self.n_joints}, "
            f"t=[{self.t_s[0]:g}, {self.t_s[-1]:g}] s, quaternion={quat})"
        )

    # ------------------------------------------------------------------ validation
    def validate(self, source: str) -> MeasurementLog:
        """Check shapes, finiteness and strictly increasing time; return ``self``.

        Args:
            source: what the log came from (a file name, ``"simulator"``, ...); starts every
                error message.

        Raises:
            SpaceIdInputError: naming ``source``, the column and the first bad sample index.
        """
        check_log_arrays(
            source,
            sample_index_label,
            self.t_s,
            self.q_rad,
            self.dq_rad_s,
            self.omega_base_body_rad_s,
            self.quat_base_to_inertial_wxyz,
        )
        return self

    def _table(self) -> FloatArray:
        """All columns side by side, shape (T, 1 + 2n + 3 [+ 4]), in CSV column order."""
        return log_table(self.t_s, self.q_rad, self.dq_rad_s, self.omega_base_body_rad_s, self.quat_base_to_inertial_wxyz)

    # ------------------------------------------------------------------ slicing
    def window(self, t_start_s: float, t_end_s: float) -> MeasurementLog:
        """The samples with ``t_start_s <= t < t_end_s`` (s), as a new log.

        Raises:
            SpaceIdInputError: if ``t_end_s <= t_start_s`` or the window holds fewer than 2 samples.
        """
        if not t_end_s > t_start_s:
            raise SpaceIdInputError(f"window: t_end_s = {float(t_end_s)!r} must be greater than t_start_s = {float(t_start_s)!r}")
        mask = (self.t_s >= t_start_s) & (self.t_s < t_end_s)
        count = int(mask.sum())
        if count < 2:
            raise SpaceIdInputError(
                f"window [{float(t_start_s)!r}, {float(t_end_s)!r}) s holds {count} samples of the log spanning "
                f"[{float(self.t_s[0])!r}, {float(self.t_s[-1])!r}] s; need at least 2"
            )
        quat = self.quat_base_to_inertial_wxyz
        return MeasurementLog(
            t_s=self.t_s[mask],
            q_rad=self.q_rad[mask],
            dq_rad_s=self.dq_rad_s[mask],
            omega_base_body_rad_s=self.omega_base_body_rad_s[mask],
            quat_base_to_inertial_wxyz=None if quat is None else quat[mask],
        )

    # ------------------------------------------------------------------ CSV
    def to_csv(self, path: PathLike) -> Path:
        """Write the log as CSV (header ``t,q1,...,qN,dq1,...,dqN,wx,wy,wz[,qw,qx,qy,qz]``), atomically.

        Values are written bit exact (``repr``). The file is first written to a temporary file in
        the same directory and then renamed over ``path``; on any error ``path`` is untouched and
        the temporary file is removed.

        Returns:
            ``path`` as a :class:`~pathlib.Path`.
        """
        return write_log_csv(Path(path), self._table(), self.n_joints, self.quat_base_to_inertial_wxyz is not None)

    @classmethod
    def from_csv(cls, path: PathLike, n_joints: int | None = None) -> MeasurementLog:
        """Read a log written by :meth:`to_csv` (or by hand in the same format).

        Args:
            path: the CSV file.
            n_joints: the robot's number of arm joints; if given, the file must have as many.

        Raises:
            SpaceIdInputError: naming the file and, where relevant, the column and the row (as
                "data row k (file line L)", both 1-based; the header is file line 1 unless blank
                lines precede it).
        """
        return cls(**read_log_csv(Path(path), n_joints))


# ---------------------------------------------------------------------- dataset folders
@dataclass
class Dataset:
    """A dataset folder: ``log.csv``, ``robot.urdf`` and, for simulated data, ``truth.json``.

    Attributes:
        log: the measurements.
        robot_urdf_path: path of ``robot.urdf`` in the folder.
        truth: the parsed ``truth.json`` (true parameters of simulated data), ``None`` if absent.
        path: the folder.
    """

    log: MeasurementLog
    robot_urdf_path: Path
    truth: dict[str, Any] | None
    path: Path


def write_dataset(directory: PathLike, log: MeasurementLog, urdf_text: str, truth: dict[str, Any] | None = None) -> Path:
    """Write a dataset folder (created with parents if needed); every file is written atomically.

    Args:
        directory: the folder; existing ``log.csv``/``robot.urdf``/``truth.json`` are replaced.
        log: the measurements, written to ``log.csv``.
        urdf_text: the robot's URDF source, written to ``robot.urdf`` unchanged.
        truth: true parameters of simulated data, written to ``truth.json`` (indent 2, sorted
            keys; numpy arrays and scalars become lists and numbers). ``None`` (real data) writes
            no ``truth.json`` and removes a stale one.

    Returns:
        The folder as a :class:`~pathlib.Path`.
    """
    directory = Path(directory)
    truth_text = None if truth is None else json.dumps(json_value(truth, ""), indent=2, sort_keys=True) + "\n"
    if directory.exists() and not directory.is_dir():
        raise SpaceIdInputError(f"{directory}: exists and is not a folder; cannot write a dataset there")
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise SpaceIdInputError(f"{directory}: cannot create the dataset folder: {exc.strerror}") from exc
    log.to_csv(directory / LOG_FILENAME)
    write_text_atomic(directory / URDF_FILENAME, urdf_text)
    truth_path = directory / TRUTH_FILENAME
    if truth_text is None:
        with suppress(FileNotFoundError):
            truth_path.unlink()
    else:
        write_text_atomic(truth_path, truth_text)
    return directory


def load_dataset(directory: PathLike, n_joints: int | None = None) -> Dataset:
    """Load a dataset folder written by :func:`write_dataset` (or assembled by hand).

    Args:
        directory: the folder with ``log.csv``, ``robot.urdf`` and optionally ``truth.json``.
        n_joints: the log must have this many joints; default: the joint count of ``robot.urdf``
            (which is loaded and validated for that).

    Raises:
        SpaceIdInputError: if the folder, ``log.csv`` or ``robot.urdf`` is missing, the log is
            malformed, or ``truth.json`` is not a JSON object.
    """
    directory = Path(directory)
    if not directory.exists():
        raise SpaceIdInputError(f"{directory}: dataset folder not found")
    if not directory.is_dir():
        raise SpaceIdInputError(f"{directory}: not a folder; expected a dataset folder with {LOG_FILENAME} and {URDF_FILENAME}")
    for name in (LOG_FILENAME, URDF_FILENAME):
        if not (directory / name).is_file():
            raise SpaceIdInputError(
                f"{directory / name}: file not found; a dataset folder needs {LOG_FILENAME} and {URDF_FILENAME}"
            )
    if n_joints is None:  # the log must fit the robot it comes with
        n_joints = load_robot(directory / URDF_FILENAME).n_joints
    log = MeasurementLog.from_csv(directory / LOG_FILENAME, n_joints=n_joints)
    truth_path = directory / TRUTH_FILENAME
    truth: dict[str, Any] | None = None
    if truth_path.exists():
        try:
            parsed = json.loads(truth_path.read_text(encoding="utf-8"))
        except json.JSONDecodeError as exc:
            raise SpaceIdInputError(f"{truth_path}: invalid JSON: {exc}") from exc
        except UnicodeDecodeError as exc:
            raise SpaceIdInputError(f"{truth_path}: not a UTF-8 text file ({exc.reason})") from exc
        except OSError as exc:
            raise SpaceIdInputError(f"{truth_path}: cannot read: {exc.strerror}") from exc
        if not isinstance(parsed, dict):
            raise SpaceIdInputError(f"{truth_path}: expected a JSON object, got a {type(parsed).__name__}")
        truth = parsed
    return Dataset(log=log, robot_urdf_path=directory / URDF_FILENAME, truth=truth, path=directory)
