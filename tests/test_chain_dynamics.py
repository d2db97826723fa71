"""The compiled dynamics of a serial revolute chain against pinocchio's RNEA and ABA, and the arm simulator with and
without them.

Independent reference: pinocchio (``pin.rnea``, ``pin.aba``) on the same models, including a chain built here with
joints about arbitrary (unaligned) axes, rotor inertias and a non-vertical gravity, which the UR5 does not exercise.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from spaceid_gym.arm import ArmRegressor, load_arm
from spaceid_gym.arm.chain_dynamics import SerialChain
from spaceid_gym.arm.excitation_design import random_fourier_trajectory
from spaceid_gym.arm.parameter_prior import ParameterPrior
from spaceid_gym.arm.torque_simulator import ArmSimulator, TrackingController


def _unaligned_chain(rng: np.random.Generator) -> pin.Model:
    """Five revolute joints about random axes, random placements and bodies, rotor inertias, tilted gravity."""
    model = pin.Model()
    parent = 0
    for i in range(5):
        axis = rng.normal(size=3)
        placement = pin.SE3(pin.exp3(rng.normal(size=3)), rng.uniform(-0.4, 0.4, size=3))
        parent = model.addJoint(parent, pin.JointModelRevoluteUnaligned(axis / np.linalg.norm(axis)), placement, f"j{i}")
        rotation = pin.exp3(rng.normal(size=3))
        inertia_c = rotation @ np.diag(rng.uniform(0.01, 0.2, size=3)) @ rotation.T
        model.appendBodyToJoint(
            parent, pin.Inertia(rng.uniform(0.5, 4.0), rng.uniform(-0.1, 0.1, size=3), inertia_c), pin.SE3.Identity()
        )
    model.armature = rng.uniform(0.0, 0.05, size=model.nv)
    model.gravity.linear = np.array([1.0, -2.0, -9.5])
    return model


def _ur5_with_drawn_parameters(seed: int) -> pin.Model:
    regressor = ArmRegressor(load_arm("ur5"), ("coulomb", "viscous"))
    return regressor.model_with_parameters(ParameterPrior().draw(regressor, np.random.default_rng(seed)))


@pytest.mark.parametrize("kind", ["ur5", "unaligned"])
def test_rnea_and_aba_equal_pinocchio(kind: str) -> None:
    """``servo``: the controller model's RNEA, then the plant's ABA at that torque (two different models)."""
    rng = np.random.default_rng(11)
    if kind == "ur5":
        plant, controller = _ur5_with_drawn_parameters(3), _ur5_with_drawn_parameters(4)
    else:
        plant = _unaligned_chain(np.random.default_rng(1))
        controller = pin.Model(plant)
        for k in range(1, controller.njoints):
            inertia = controller.inertias[k]
            controller.inertias[k] = pin.Inertia(inertia.mass * 1.2, inertia.lever + 0.01, inertia.inertia * 0.9)
        controller.armature = plant.armature * 0.5
    plant_chain, controller_chain = SerialChain.from_pinocchio(plant), SerialChain.from_pinocchio(controller)
    assert plant_chain is not None and controller_chain is not None
    plant_data, controller_data = plant.createData(), controller.createData()
    for _ in range(100):
        q, dq, command = rng.uniform(-3.0, 3.0, size=(3, plant.nv))
        tau, ddq = plant_chain.servo(controller_chain, q, dq, command)
        expected_tau = pin.rnea(controller, controller_data, q, dq, command).copy()
        np.testing.assert_allclose(tau, expected_tau, rtol=0, atol=1e-12 * np.abs(expected_tau).max())
        expected_ddq = pin.aba(plant, plant_data, q, dq, tau).copy()
        np.testing.assert_allclose(ddq, expected_ddq, rtol=0, atol=1e-12 * np.abs(expected_ddq).max())


def test_only_serial_revolute_chains_are_compiled() -> None:
    model = pin.Model()
    joint = model.addJoint(0, pin.JointModelPX(), pin.SE3.Identity(), "slider")
    model.appendBodyToJoint(joint, pin.Inertia.Random(), pin.SE3.Identity())
    assert SerialChain.from_pinocchio(model) is None
    branched = pin.Model()
    for name in ("a", "b"):  # two joints on the base: a tree, not a chain
        branched.addJoint(0, pin.JointModelRZ(), pin.SE3.Identity(), name)
    assert SerialChain.from_pinocchio(branched) is None


def test_simulator_runs_the_same_with_pinocchio_and_compiled_dynamics() -> None:
    robot = load_arm("ur5")
    regressor = ArmRegressor(robot, ("coulomb", "viscous"))
    parameters = ParameterPrior().draw(regressor, np.random.default_rng(4))
    trajectory = random_fourier_trajectory(robot, np.random.default_rng(5))
    runs = []
    for compiled in (True, False):
        simulator = ArmSimulator(robot, parameters, controller=TrackingController(), internal_rate_hz=500.0)
        assert simulator._compiled is not None
        if not compiled:
            simulator._compiled = None  # pinocchio's rnea and aba, one call at a time
        runs.append(simulator.run(trajectory, 4.0, np.random.default_rng(0)).clean)
    fast, reference = runs
    for name in ("q_rad", "dq_rad_s", "ddq_rad_s2", "effort"):
        a, b = getattr(fast, name), getattr(reference, name)
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-12 * np.abs(b).max(), err_msg=name)
