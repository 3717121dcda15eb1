"""The robot model from a URDF (Pinocchio) and the robots' generalized-momentum observer.

The real robot here is the DFKI double pendulum (../shared/external/double_pendulum): its URDF
as the lab publishes it, and the lab's own equations of motion to compare with."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from transparency_ros.core.estimator import EstimatorError
from transparency_ros.core.momentum_observer import RobotMomentumObserver
from transparency_ros.core.robot_model import RobotModel, UrdfError
from transparency_ros.synth.robots import chain_urdf as chain
from transparency_ros.synth.robots import simulate_chain

SHARED = Path(__file__).resolve().parents[1] / "data" / "double_pendulum"  # the lab's files
URDF = SHARED / "pendubot.urdf"


def lab_equations(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The lab's M(q) and g(q) (their plant.py, with G of the opposite sign)."""
    p = yaml.safe_load((SHARED / "model_parameters.yml").read_text())
    c2 = math.cos(q[1])
    m00 = (
        p["I1"] + p["I2"] + p["m2"] * p["l1"] ** 2 + 2 * p["m2"] * p["l1"] * p["r2"] * c2
        + p["gr"] ** 2 * p["Ir"] + p["Ir"]
    )  # fmt: skip
    m01 = p["I2"] + p["m2"] * p["l1"] * p["r2"] * c2 - p["gr"] * p["Ir"]
    m11 = p["I2"] + p["gr"] ** 2 * p["Ir"]
    g1 = p["m2"] * p["g"] * p["r2"] * math.sin(q[0] + q[1])
    g0 = p["m1"] * p["g"] * p["r1"] * math.sin(q[0]) + p["m2"] * p["g"] * p["l1"] * math.sin(q[0])
    return np.array([[m00, m01], [m01, m11]]), np.array([g0 + g1, g1])


def test_the_labs_urdf_loads_with_a_note_and_its_gravity_is_the_labs() -> None:
    """Its fixed joint names a `world` link the file never defines (urdfdom refuses it):
    taken as the world, with a note. Gravity agrees with the lab's equations; the mass matrix
    does not (the URDF gives the inertias about the joint axes as about the centres of mass,
    and has no rotor inertia), which the lab's README says too."""
    model = RobotModel.from_urdf(URDF)
    assert model.joint_names == ("Joint1", "Joint2")
    assert len(model.notes) == 1 and "'base_weld'" in model.notes[0] and "world" in model.notes[0]
    for q in ([0.3, 0.5], [1.0, -0.7], [2.0, 1.0], [-2.5, 3.0]):
        mass, gravity = lab_equations(np.array(q))
        assert model.gravity(np.array(q)) == pytest.approx(gravity, abs=1e-4)
        urdf_mass = model.mass_matrix(np.array(q))
        assert urdf_mass == pytest.approx(urdf_mass.T)
        # the URDF's known fault: the elbow's own inertia 0.092 kg m^2 against the lab's 0.053
        assert urdf_mass[1, 1] / mass[1, 1] == pytest.approx(1.73, abs=0.01)
    assert model.friction.coulomb.tolist() == [0.16, 0.12]  # <dynamics friction=...>
    assert model.friction.viscous.tolist() == [0.001, 0.001]


def test_a_urdf_as_robot_description_string_and_the_names_of_joint_states() -> None:
    model = RobotModel.from_urdf(chain(3))
    assert model.source == "robot_description" and model.notes == []
    order = model.index(["j2", "other", "j0", "j1"])
    assert order.tolist() == [2, 3, 0]
    with pytest.raises(UrdfError, match=r"/joint_states has no joint 'j1' of robot_description"):
        model.index(["j0", "j2"])


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("<robot name='r'><link name='a'/", "robot_description: not XML"),
        ("<model name='r'/>", "root element is <model>, not <robot>"),
        (
            "<robot name='r'><link name='a'/><joint name='j' type='revolute'>"
            "<parent link='a'/><child link='b'/></joint></robot>",
            "joint 'j' names child link 'b', which the file does not define",
        ),
        (
            "<robot name='r'><link name='a'/><link name='b'/><joint name='j' type='floating'>"
            "<parent link='a'/><child link='b'/></joint></robot>",
            "joint 'j' is of type 'floating'",
        ),
    ],
)
def test_a_urdf_that_does_not_load_names_what_is_wrong(text: str, message: str) -> None:
    with pytest.raises(UrdfError, match=message):
        RobotModel.from_urdf(text)


def test_a_missing_urdf_file_is_named(tmp_path: Path) -> None:
    with pytest.raises(UrdfError, match=r"nothing\.urdf: cannot read the URDF"):
        RobotModel.from_urdf(tmp_path / "nothing.urdf")


def test_the_observer_finds_an_external_torque_on_the_joint_it_acts_on() -> None:
    """A 0.3 N m push on the middle joint of a 3-link chain for 0.2 s while the chain moves:
    the residual of that joint rises to it with the observer's lag; the others stay near 0
    (the model is the true one here)."""
    model = RobotModel.from_urdf(chain(3))
    tau_ext = np.zeros((2000, 3))
    tau_ext[1000:1200, 1] = 0.3
    stamps, q, v, tau = simulate_chain(model, tau_ext)
    observer = RobotMomentumObserver(model, gain_per_s=50.0)
    r = observer.run(stamps, q, v, tau)
    assert np.max(np.abs(r[:1000])) < 0.01  # no push, no residual
    # first-order lag: 1 - exp(-50 * 0.1) = 99 % after 0.1 s
    assert r[1100, 1] == pytest.approx(0.3, rel=0.03)
    assert np.max(np.abs(r[1000:1200, [0, 2]])) < 0.03
    assert np.max(np.abs(r[1400:, 1])) < 0.01  # it decays once the push ends


def test_the_observer_says_what_is_wrong_with_a_sample() -> None:
    observer = RobotMomentumObserver(RobotModel.from_urdf(chain(2)), gain_per_s=[20.0, 30.0])
    observer.update(0, np.zeros(2), np.zeros(2), np.zeros(2))
    with pytest.raises(EstimatorError, match="velocity is not finite"):
        observer.update(1_000_000, np.zeros(2), np.array([0.0, math.nan]), np.zeros(2))
    with pytest.raises(EstimatorError, match="torque: expected 2 joints"):
        observer.update(1_000_000, np.zeros(2), np.zeros(2), np.zeros(3))
    with pytest.raises(EstimatorError, match="stamps must increase"):
        observer.update(0, np.zeros(2), np.zeros(2), np.zeros(2))
    with pytest.raises(EstimatorError, match="gains K_o must be > 0"):
        RobotMomentumObserver(RobotModel.from_urdf(chain(2)), gain_per_s=[20.0, 0.0])
