"""The fixed-base arm model: UR5 URDF vs UR's DH table, the regressor vs inverse dynamics, friction, base parameters.

Independent references: the DH table (forward kinematics, CoMs, potential and kinetic energy
computed here from the table and the documented cylinder approximations, with finite differences),
pinocchio's RNEA, the friction formulas written out, and closed-form parameter groupings.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from spaceid_gym.arm import ArmRegressor, BaseParameterSet, FrictionModel, load_arm, stack
from spaceid_gym.arm.arm_robot import arm_from_urdf_text
from spaceid_gym.errors import SpaceIdInputError

# UR5 (CB3) DH table and dynamics from UR's "DH parameters for calculations of kinematics and dynamics"
DH_A = np.array([0.0, -0.425, -0.39225, 0.0, 0.0, 0.0])
DH_D = np.array([0.089159, 0.0, 0.0, 0.10915, 0.09465, 0.0823])
DH_ALPHA = np.array([np.pi / 2, 0.0, 0.0, np.pi / 2, -np.pi / 2, 0.0])
MASS = np.array([3.7, 8.393, 2.275, 1.219, 1.219, 0.1879])
COM_DH = np.array(
    [
        [0, -0.02561, 0.00193],
        [0.2125, 0, 0.11336],
        [0.15, 0, 0.0265],
        [0, -0.0018, 0.01634],
        [0, 0.0018, 0.01634],
        [0, 0, -0.001159],
    ]
)
# the documented inertia approximation: solid cylinders (radius m, length m, axis in DH frame i)
CYLINDERS = [(0.06, 0.12, 2), (0.06, 0.425, 0), (0.05, 0.39225, 0), (0.045, 0.12, 2), (0.045, 0.12, 2), (0.0375, 0.03, 2)]
G = 9.81


def dh_transform(theta: float, d: float, a: float, alpha: float) -> np.ndarray:
    """Standard DH: Rz(theta) Tz(d) Tx(a) Rx(alpha), 4x4."""
    ct, st, ca, sa = np.cos(theta), np.sin(theta), np.cos(alpha), np.sin(alpha)
    return np.array([[ct, -st * ca, st * sa, a * ct], [st, ct * ca, -ct * sa, a * st], [0, sa, ca, d], [0, 0, 0, 1.0]])


def dh_frames(q: np.ndarray) -> list[np.ndarray]:
    """Base-to-DH-frame-i transforms, i = 0..6."""
    frames = [np.eye(4)]
    for i in range(6):
        frames.append(frames[-1] @ dh_transform(q[i], DH_D[i], DH_A[i], DH_ALPHA[i]))
    return frames


def cylinder_inertia(i: int) -> np.ndarray:
    radius, length, axis = CYLINDERS[i]
    inertia = np.full(3, MASS[i] * (3 * radius**2 + length**2) / 12)
    inertia[axis] = MASS[i] * radius**2 / 2
    return np.diag(inertia)


def com_world(q: np.ndarray) -> np.ndarray:
    """CoM of each link in the base frame from the DH table, shape (6, 3)."""
    frames = dh_frames(q)
    return np.array([frames[i + 1][:3, :3] @ COM_DH[i] + frames[i + 1][:3, 3] for i in range(6)])


@pytest.fixture(scope="module")
def ur5():
    return load_arm("ur5")


@pytest.fixture(scope="module")
def rng_states(ur5):
    return ur5.sample_states(np.random.default_rng(7), 40)


# ---------------------------------------------------------------------------------------- URDF
def test_urdf_forward_kinematics_match_dh_table(ur5) -> None:
    data = ur5.create_data()
    tool = ur5.model.getFrameId("tool0")
    rng = np.random.default_rng(1)
    for _ in range(20):
        q = rng.uniform(-2 * np.pi, 2 * np.pi, 6)
        pin.framesForwardKinematics(ur5.model, data, q)
        frames = dh_frames(q)
        np.testing.assert_allclose(data.oMf[tool].homogeneous, frames[6], atol=1e-12, rtol=0)
        for k in range(1, 7):  # joint frame k = DH frame k-1 rotated by q_k about z
            rz = dh_transform(q[k - 1], 0.0, 0.0, 0.0)
            np.testing.assert_allclose(data.oMi[k].homogeneous, frames[k - 1] @ rz, atol=1e-12, rtol=0)


def test_urdf_masses_coms_and_limits(ur5) -> None:
    assert ur5.n_joints == 6
    np.testing.assert_array_equal([ur5.model.inertias[k].mass for k in range(1, 7)], MASS)
    np.testing.assert_array_equal(ur5.torque_limit_Nm, [150, 150, 150, 28, 28, 28])
    np.testing.assert_allclose(ur5.dq_limit_rad_s, np.pi)
    np.testing.assert_allclose(ur5.q_upper_rad, 2 * np.pi)
    np.testing.assert_allclose(ur5.q_lower_rad, -2 * np.pi)
    np.testing.assert_array_equal(ur5.gravity_m_s2, [0, 0, -G])
    data = ur5.create_data()
    rng = np.random.default_rng(2)
    for _ in range(10):
        q = rng.uniform(-np.pi, np.pi, 6)
        pin.forwardKinematics(ur5.model, data, q)
        pin_com = [data.oMi[k].act(ur5.model.inertias[k].lever) for k in range(1, 7)]
        np.testing.assert_allclose(pin_com, com_world(q), atol=1e-12, rtol=0)


def test_gravity_torque_is_the_gradient_of_potential_energy(ur5) -> None:
    """tau(q, 0, 0) = dU/dq with U = sum m g z_com from the DH table (central differences)."""
    regressor = ArmRegressor(ur5, friction=None)
    p = regressor.nominal_parameters()
    rng = np.random.default_rng(3)
    h = 1e-6
    for _ in range(5):
        q = rng.uniform(-np.pi, np.pi, 6)
        grad = np.empty(6)
        for j in range(6):
            e = np.zeros(6)
            e[j] = h
            grad[j] = (MASS @ com_world(q + e)[:, 2] - MASS @ com_world(q - e)[:, 2]) * G / (2 * h)
        tau = regressor.torque(q, np.zeros(6), np.zeros(6), p)[0]
        np.testing.assert_allclose(tau, grad, atol=1e-7, rtol=0)
        assert np.abs(tau[1:3]).max() > 1.0  # the check is not vacuous


def test_kinetic_energy_matches_dh_table_and_cylinders(ur5) -> None:
    """0.5 dq' M(q) dq from the regressor = sum of link kinetic energies from the DH kinematics."""
    regressor = ArmRegressor(ur5, friction=None)
    p = regressor.nominal_parameters()
    rng = np.random.default_rng(4)
    h = 1e-6
    for _ in range(5):
        q, dq = rng.uniform(-np.pi, np.pi, 6), rng.uniform(-1, 1, 6)
        M_dq = regressor.torque(q, np.zeros(6), dq, p)[0] - regressor.torque(q, np.zeros(6), np.zeros(6), p)[0]
        plus, minus = dh_frames(q + h * dq), dh_frames(q - h * dq)
        energy = 0.0
        for i in range(6):
            v = (com_world(q + h * dq)[i] - com_world(q - h * dq)[i]) / (2 * h)
            R_dot = (plus[i + 1][:3, :3] - minus[i + 1][:3, :3]) / (2 * h)
            R = dh_frames(q)[i + 1][:3, :3]
            W = R_dot @ R.T  # [omega]x in the base frame
            omega = np.array([W[2, 1], W[0, 2], W[1, 0]])
            inertia_world = R @ cylinder_inertia(i) @ R.T
            energy += 0.5 * MASS[i] * v @ v + 0.5 * omega @ inertia_world @ omega
        assert 0.5 * dq @ M_dq == pytest.approx(energy, rel=1e-8)


# ---------------------------------------------------------------------------------------- regressor
@pytest.mark.parametrize("friction", [None, ("coulomb", "viscous"), ("coulomb", "viscous", "stribeck", "offset")])
def test_regressor_times_urdf_parameters_is_rnea(ur5, rng_states, friction) -> None:
    regressor = ArmRegressor(ur5, friction=friction)
    q, dq, ddq = rng_states
    Y = regressor.regressor(q, dq, ddq)
    assert Y.shape == (40, 6, regressor.n_parameters)
    data = ur5.create_data()
    tau = np.array([pin.rnea(ur5.model, data, *state) for state in zip(q, dq, ddq, strict=True)])
    np.testing.assert_allclose(Y @ regressor.nominal_parameters(), tau, atol=1e-10, rtol=0)
    assert np.abs(tau).max() > 10.0


def test_armature_columns_match_pinocchio_armature(ur5, rng_states) -> None:
    """Rotor inertias: ``Y p`` equals pinocchio's inverse dynamics of a model with ``armature`` set (independent code path)."""
    regressor = ArmRegressor(ur5, friction=("coulomb",), armature=True)
    assert regressor.parameter_names[-6:] == tuple(f"joint{j}_armature_kgm2" for j in range(1, 7))
    p = regressor.nominal_parameters()
    p[-6:] = [0.4, 0.35, 0.2, 0.05, 0.04, 0.03]
    model = regressor.model_with_parameters(p)
    np.testing.assert_array_equal(model.armature, p[-6:])
    data = model.createData()
    q, dq, ddq = rng_states
    tau = np.array([pin.rnea(model, data, *state) for state in zip(q, dq, ddq, strict=True)])
    np.testing.assert_allclose(regressor.torque(q, dq, ddq, p), tau, atol=1e-10, rtol=0)
    assert np.abs(ddq @ np.diag(p[-6:])).max() > 0.1  # the armature term is not negligible in this check
    np.testing.assert_array_equal(regressor.parameters_of_model(model)[-6:], p[-6:])


def test_parameter_names_and_layout_match_a_random_model(ur5, rng_states) -> None:
    """Parameters written out by hand from random bodies (mass, CoM, inertia at the CoM) reproduce RNEA."""
    regressor = ArmRegressor(ur5, friction=("coulomb", "viscous"))
    names = regressor.parameter_names
    assert names[:10] == (
        "link1_mass_kg",
        "link1_mcx_kgm",
        "link1_mcy_kgm",
        "link1_mcz_kgm",
        "link1_ixx_kgm2",
        "link1_ixy_kgm2",
        "link1_iyy_kgm2",
        "link1_ixz_kgm2",
        "link1_iyz_kgm2",
        "link1_izz_kgm2",
    )
    assert names[-4:] == ("joint5_coulomb_Nm", "joint5_viscous_Nms", "joint6_coulomb_Nm", "joint6_viscous_Nms")
    rng = np.random.default_rng(5)
    model = pin.Model(ur5.model)
    p = np.zeros(regressor.n_parameters)
    for k in range(1, 7):
        mass, com = rng.uniform(0.5, 5), rng.uniform(-0.2, 0.2, 3)
        A = rng.normal(size=(3, 3))
        inertia_com = A @ A.T * 0.01 + 0.01 * np.eye(3)
        model.inertias[k] = pin.Inertia(mass, com, inertia_com)
        S = np.array([[0, -com[2], com[1]], [com[2], 0, -com[0]], [-com[1], com[0], 0]])
        inertia_origin = inertia_com + mass * S.T @ S
        values = {"mass_kg": mass, "mcx_kgm": mass * com[0], "mcy_kgm": mass * com[1], "mcz_kgm": mass * com[2]}
        for axes, (r, c) in {"xx": (0, 0), "xy": (0, 1), "yy": (1, 1), "xz": (0, 2), "yz": (1, 2), "zz": (2, 2)}.items():
            values[f"i{axes}_kgm2"] = inertia_origin[r, c]
        for field, value in values.items():
            p[names.index(f"link{k}_{field}")] = value
    q, dq, ddq = rng_states
    data = model.createData()
    tau = np.array([pin.rnea(model, data, *state) for state in zip(q, dq, ddq, strict=True)])
    np.testing.assert_allclose(regressor.torque(q, dq, ddq, p), tau, atol=1e-10, rtol=0)
    # and the reverse map: model_with_parameters / parameters_of_model
    np.testing.assert_allclose(
        regressor.parameters_of_model(regressor.model_with_parameters(p)), p * (np.arange(p.size) < 60), atol=1e-14
    )


@pytest.mark.parametrize("smoothing", [0.0, 0.01])
def test_friction_columns_match_the_friction_formula(ur5, rng_states, smoothing) -> None:
    friction = FrictionModel(
        ("offset", "stribeck", "viscous", "coulomb"), coulomb_smoothing_rad_s=smoothing, stribeck_velocity_rad_s=0.05
    )
    assert friction.terms == ("coulomb", "viscous", "stribeck", "offset")  # canonical order
    regressor = ArmRegressor(ur5, friction=friction)
    q, dq, ddq = rng_states
    dq = dq.copy()
    dq[0] = [0.0, 1e-3, -1e-3, 0.02, -0.05, 0.3]  # around zero speed too
    rng = np.random.default_rng(6)
    fc, fv, fs, f0 = rng.uniform(0.5, 5, 6), rng.uniform(0.1, 2, 6), rng.uniform(5, 8, 6), rng.uniform(-1, 1, 6)
    p = np.zeros(regressor.n_parameters)
    names = regressor.parameter_names
    for j in range(6):
        p[names.index(f"joint{j + 1}_coulomb_Nm")] = fc[j]
        p[names.index(f"joint{j + 1}_viscous_Nms")] = fv[j]
        p[names.index(f"joint{j + 1}_stribeck_Nm")] = fs[j] - fc[j]
        p[names.index(f"joint{j + 1}_offset_Nm")] = f0[j]
    s = np.sign(dq) if smoothing == 0 else np.tanh(dq / smoothing)
    expected = fc * s + fv * dq + (fs - fc) * np.exp(-((dq / 0.05) ** 2)) * s + f0
    np.testing.assert_allclose(regressor.torque(q, dq, ddq, p), expected, atol=1e-12, rtol=0)
    coefficients = np.stack([fc, fv, fs - fc, f0], axis=1)
    np.testing.assert_allclose(friction.torque(dq, coefficients), expected, atol=1e-12, rtol=0)


def test_friction_model_rejects_bad_options() -> None:
    with pytest.raises(SpaceIdInputError, match="unknown term"):
        FrictionModel(("coulomb", "dahl"))
    with pytest.raises(SpaceIdInputError, match="duplicated"):
        FrictionModel(("coulomb", "coulomb"))
    with pytest.raises(SpaceIdInputError, match="stribeck_velocity_rad_s"):
        FrictionModel(stribeck_velocity_rad_s=0.0)


def test_stack_is_sample_major(ur5, rng_states) -> None:
    regressor = ArmRegressor(ur5)
    Y = regressor.regressor(*rng_states)
    tau = np.arange(40 * 6, dtype=float).reshape(40, 6)
    W, y = stack(Y, tau)
    assert W.shape == (240, regressor.n_parameters)
    np.testing.assert_array_equal(W[3 * 6 + 2], Y[3, 2])
    assert y[3 * 6 + 2] == tau[3, 2]
    with pytest.raises(SpaceIdInputError, match="stack"):
        stack(Y, tau[:, :5])


def test_regressor_rejects_bad_states(ur5) -> None:
    regressor = ArmRegressor(ur5)
    with pytest.raises(SpaceIdInputError, match=r"dq_rad_s must have shape \(T, 6\)"):
        regressor.regressor(np.zeros((2, 6)), np.zeros((2, 5)), np.zeros((2, 6)))
    with pytest.raises(SpaceIdInputError, match="q_rad has a non-finite value at sample 1"):
        regressor.regressor(np.array([np.zeros(6), np.full(6, np.nan)]), np.zeros((2, 6)), np.zeros((2, 6)))
    with pytest.raises(SpaceIdInputError, match="parameters must have shape"):
        regressor.torque(np.zeros(6), np.zeros(6), np.zeros(6), np.zeros(3))


# ---------------------------------------------------------------------------------------- base parameters
@pytest.fixture(scope="module")
def base_cv(ur5):
    return ArmRegressor(ur5, ("coulomb", "viscous")), BaseParameterSet.from_regressor(
        ArmRegressor(ur5, ("coulomb", "viscous")), np.random.default_rng(11)
    )


def test_ur5_base_parameter_rank(ur5, base_cv) -> None:
    regressor, base = base_cv
    assert base.rank == 48  # 36 rigid-body + 12 friction
    rigid = BaseParameterSet.from_regressor(ArmRegressor(ur5, None), np.random.default_rng(12))
    assert rigid.rank == 36
    # an independent rank estimate (SVD, numpy's default tolerance) on fresh states
    q, dq, ddq = ur5.sample_states(np.random.default_rng(13), 200)
    W, _ = stack(regressor.regressor(q, dq, ddq), np.zeros((200, 6)))
    assert np.linalg.matrix_rank(W) == 48
    assert np.sort(base.r_diag)[::-1][47] > 1e-3 > 1e-12 > np.sort(base.r_diag)[::-1][48]  # a clear gap


def test_base_parameters_reproduce_torques_on_fresh_samples(ur5, base_cv) -> None:
    regressor, base = base_cv
    rng = np.random.default_rng(21)
    q, dq, ddq = ur5.sample_states(rng, 100)
    Y = regressor.regressor(q, dq, ddq)
    for p in (regressor.nominal_parameters(), rng.normal(size=regressor.n_parameters)):
        beta = base.to_base(p)
        np.testing.assert_allclose(base.base_regressor(Y) @ beta, Y @ p, atol=1e-10, rtol=0)
    # the null space changes no torque; full_parameters goes back
    N = base.null_space()
    assert N.shape == (regressor.n_parameters, regressor.n_parameters - 48)
    np.testing.assert_allclose(base.K @ N, 0, atol=1e-12)
    np.testing.assert_allclose(Y @ N, 0, atol=1e-9)
    p = regressor.nominal_parameters()
    np.testing.assert_allclose(base.full_parameters(base.to_base(p), reference=p), p, atol=1e-12)
    p_other = base.full_parameters(base.to_base(p))
    np.testing.assert_allclose(base.to_base(p_other), base.to_base(p), atol=1e-12)


def test_base_parameter_groupings_are_the_classical_ones(base_cv) -> None:
    """Closed forms: link 3's mass sits at the elbow, a2 = -0.425 m from the shoulder, in link 2's frame."""
    regressor, base = base_cv
    names = list(regressor.parameter_names)
    row = {names[i]: r for r, i in enumerate(base.independent)}
    m3 = names.index("link3_mass_kg")
    assert "link3_mass_kg" not in row and "link1_mass_kg" not in row
    assert base.K[row["link2_mcx_kgm"], m3] == pytest.approx(DH_A[1], abs=1e-9)
    assert base.K[row["link2_izz_kgm2"], m3] == pytest.approx(DH_A[1] ** 2, abs=1e-9)
    assert base.K[row["link3_mcx_kgm"], names.index("link4_mass_kg")] == pytest.approx(DH_A[2], abs=1e-9)
    assert base.names[row["link2_mcx_kgm"]].startswith("link2_mcx_kgm - 0.425 link3_mass_kg")
    for j in range(1, 7):  # friction is always identifiable and never regrouped
        assert f"joint{j}_coulomb_Nm" in base.names and f"joint{j}_viscous_Nms" in base.names


# ---------------------------------------------------------------------------------------- other URDFs
ARM3 = """<robot name="arm3">
  <link name="world"/>
  <joint name="mount" type="fixed"><parent link="world"/><child link="base"/><origin xyz="0.1 0 0.2" rpy="0 0 0.3"/></joint>
  <link name="base"><inertial><mass value="2"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><origin xyz="0 0 0.1"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" velocity="2" effort="50"/></joint>
  <link name="l1"><inertial><origin xyz="0.01 0.02 0.1" rpy="0.1 0.2 0.3"/><mass value="1.5"/>
    <inertia ixx="0.02" ixy="0.001" ixz="0" iyy="0.03" iyz="0" izz="0.01"/></inertial></link>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0 0.05 0.2" rpy="0.5 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-2" upper="2" velocity="2" effort="50"/></joint>
  <link name="l2"><inertial><origin xyz="0.15 0 0"/><mass value="1.0"/>
    <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>
  <joint name="j3" type="revolute"><parent link="l2"/><child link="l3"/><origin xyz="0.3 0 0"/><axis xyz="1 0 0"/>
    <limit lower="-2" upper="2" velocity="3" effort="20"/></joint>
  <link name="l3"><inertial><origin xyz="0.05 0.01 0"/><mass value="0.5"/>
    <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.002" iyz="0" izz="0.002"/></inertial></link>
  <joint name="tool" type="fixed"><parent link="l3"/><child link="tool_link"/><origin xyz="0.1 0 0"/></joint>
  <link name="tool_link"><inertial><mass value="0.2"/><inertia ixx="1e-4" ixy="0" ixz="0" iyy="1e-4" iyz="0" izz="1e-4"/></inertial></link>
</robot>"""


def test_any_fixed_base_serial_urdf_works(tmp_path) -> None:
    path = tmp_path / "arm3.urdf"
    path.write_text(ARM3)
    robot = load_arm(path, ddq_limit_rad_s2=[5, 6, 7])
    assert robot.joint_names == ("j1", "j2", "j3") and robot.link_names == ("l1", "l2", "l3")
    np.testing.assert_array_equal(robot.ddq_limit_rad_s2, [5, 6, 7])
    regressor = ArmRegressor(robot, ("coulomb", "viscous"))
    q, dq, ddq = robot.sample_states(np.random.default_rng(0), 20)
    data = robot.create_data()
    tau = np.array([pin.rnea(robot.model, data, *s) for s in zip(q, dq, ddq, strict=True)])
    np.testing.assert_allclose(regressor.torque(q, dq, ddq, regressor.nominal_parameters()), tau, atol=1e-10, rtol=0)
    base = BaseParameterSet.from_regressor(regressor, np.random.default_rng(1), n_samples=100)
    np.testing.assert_allclose(
        base.base_regressor(regressor.regressor(q, dq, ddq)) @ base.to_base(regressor.nominal_parameters()), tau, atol=1e-10
    )


def _edit(old: str, new: str) -> str:
    assert old in ARM3
    return ARM3.replace(old, new, 1)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (_edit('<joint name="mount" type="fixed">', '<joint name="mount" type="floating">'), "mount.*free-floating root"),
        (_edit('name="j2" type="revolute"', 'name="j2" type="prismatic"'), "j2.*prismatic joints are not supported"),
        (_edit('name="j3" type="revolute"', 'name="j3" type="continuous"'), "j3.*continuous joints are not supported"),
        (_edit('<parent link="l2"/><child link="l3"/>', '<parent link="l1"/><child link="l3"/>'), "j3.*branch"),
        (
            _edit('<limit lower="-2" upper="2" velocity="3" effort="20"/>', '<limit lower="-2" upper="2"/>'),
            "j3.*velocity, effort",
        ),
        (_edit('velocity="3" effort="20"', 'velocity="3" effort="0"'), "j3.*effort > 0"),
        ("<robot><link", "not valid URDF XML"),
    ],
)
def test_load_arm_rejects_what_it_cannot_handle(tmp_path, text, message) -> None:
    with pytest.raises(SpaceIdInputError, match=message):
        arm_from_urdf_text(text, "arm3.urdf")


def test_load_arm_missing_file_and_bad_options(tmp_path) -> None:
    with pytest.raises(SpaceIdInputError, match=r"not a shipped arm.*no such URDF file"):
        load_arm(tmp_path / "missing.urdf")
    with pytest.raises(SpaceIdInputError, match="ddq_limit_rad_s2"):
        load_arm("ur5", ddq_limit_rad_s2=-1.0)
    with pytest.raises(SpaceIdInputError, match="gravity_m_s2"):
        load_arm("ur5", gravity_m_s2=(0, 0))
