"""The robot's model carrying what the discrepancy tool names, simulated in short windows from
the recorded states (multiple shooting): checked on a simulated chain whose truth differs from
its URDF in known ways."""

from __future__ import annotations

import math

import numpy as np

from transparency_ros.analysis.discrepancy import robot_shooting as rs
from transparency_ros.analysis.discrepancy.robot_effects import library
from transparency_ros.analysis.robot_data import JointRecording
from transparency_ros.core.robot_model import RobotModel
from transparency_ros.synth.robots import chain_urdf, simulate_chain


def test_the_named_effects_bring_the_simulated_windows_onto_the_recorded_motion() -> None:
    """The chain's motors act 4 ms late and apply 0.8 of their command on the first joint, and
    each joint has 0.1 N m more Coulomb friction than its URDF says. The URDF's windows drift
    from the recorded motion; with those effects named the error is a small part of it, and
    each effect is needed."""
    urdf = RobotModel.from_urdf(chain_urdf(2))
    truth = RobotModel.from_urdf(chain_urdf(2, friction=0.15))
    n = 3000
    stamps, q, v, command = simulate_chain(truth, np.zeros((n, 2)), delay_steps=4)
    # what moved the robot was 0.8 of the first joint's recorded command
    run = JointRecording("run", stamps, urdf.joint_names, q, v, command / np.array([0.8, 1.0]))
    effects = {e.name: e for e in library(urdf.joint_names, np.full(2, 5.0), np.full(2, 5.0))}
    named = [
        (effects["command_delay"], np.array([0.0045])),
        (effects["torque_gain[j0]"], np.array([0.8])),
        (effects["coulomb_friction[j0]"], np.array([0.1])),
        (effects["coulomb_friction[j1]"], np.array([0.1])),
    ]
    before, windows, diverged = rs.window_errors(urdf, [], [run])
    after, _, diverged_after = rs.window_errors(urdf, named, [run])
    assert windows == 14 and diverged == diverged_after == 0
    assert np.all(after < 0.2 * before)
    for k in range(len(named)):  # each one is needed
        without, _, _ = rs.window_errors(urdf, named[:k] + named[k + 1 :], [run])
        assert np.any(without > 2 * after)


def test_a_window_that_leaves_the_motion_counts_at_its_bound() -> None:
    t = np.arange(11) * 0.01
    recorded = np.zeros((11, 1))

    def rate(q: np.ndarray, v: np.ndarray, u: np.ndarray) -> np.ndarray:
        return np.array([1e6])  # a model that throws the joint away

    error, ok = rs._window(rate, (np.zeros(1), np.zeros(1)), np.zeros((11, 1)), recorded, t)
    assert not ok and error.shape == (10, 1)
    assert error[0, 0] == 0.0 and error[-1, 0] == rs.DIVERGED_RAD
    _, windows, _ = rs.window_errors(
        RobotModel.from_urdf(chain_urdf(1)), [], [
            JointRecording("short", np.arange(20, dtype=np.int64) * 2_000_000, ("j0",),
                           np.zeros((20, 1)), np.zeros((20, 1)), np.zeros((20, 1)))
        ],
    )  # fmt: skip
    assert windows == 0
    assert math.isnan(rs.window_errors(RobotModel.from_urdf(chain_urdf(1)), [], [])[0][0])
