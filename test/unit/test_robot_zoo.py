"""How benchmarks/robot_zoo.py states the truth of a robot and scores the tool against it: the
figures of the robot discrepancy tool's survey rest on these rules."""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

BENCHMARKS = Path(__file__).resolve().parents[2] / "benchmarks"
sys.path.insert(0, str(BENCHMARKS))

import robot_zoo  # noqa: E402


def _robot(*effects: dict[str, Any]) -> dict[str, Any]:
    return {"seed": 0, "pendubot": False, "cf": [0.2, 0.1], "b": [0.002, 0.002],
            "lag_s": 0.0005, "amplitude": [1.0, 0.6], "effects": list(effects)}  # fmt: skip


def _found(effect: str, joint: str | None, **params: float) -> dict[str, Any]:
    return {"effect": effect, "joint": joint, "parameters": params}


def test_a_required_delay_counts_the_commands_hold_and_the_motors_lag() -> None:
    truth = robot_zoo.answers(_robot({"kind": "sensor_delay", "joint": None, "delay_s": 0.005}))
    # (400 Hz control: the command is held 2.5 ms, half of it on average; the lag 0.5 ms)
    assert truth["required"]["sensor_delay"]["delay_s"] == pytest.approx(0.005 + 0.00125 + 0.0005)
    # the balance cannot tell the two delays apart: the twin names it
    right = robot_zoo.score([_found("command_delay", None, delay_s=0.0068)], truth)
    assert right["right"] and right["named"] == ["sensor_delay"]
    far = robot_zoo.score([_found("command_delay", None, delay_s=0.0030)], truth)
    assert far["missed"] == ["sensor_delay"] and not far["right"]


def test_a_required_coulomb_friction_is_the_robots_against_its_urdf() -> None:
    truth = robot_zoo.answers(_robot({"kind": "coulomb_friction", "joint": 0, "coulomb_nm": 0.3}))
    # the lab's law cf atan(100 q') levels off at cf pi / 2; the URDF says 0.16 (Joint1)
    expected = 0.2 * math.pi / 2 - 0.16 + 0.3
    assert truth["required"]["coulomb_friction[Joint1]"]["coulomb_nm"] == pytest.approx(expected)


def test_what_is_named_outside_required_and_allowed_is_a_false_finding() -> None:
    truth = robot_zoo.answers(_robot())
    assert truth["required"] == {}
    found = [
        _found("parameter_drift", "Joint2", inertia_scale=0.56),  # the URDF's fault: allowed
        _found("sensor_delay", None, delay_s=0.002),  # the motors' own lag and hold
        _found("payload", "Joint2", mass_kg=0.2),  # no payload on this robot
    ]
    scored = robot_zoo.score(found, truth)
    assert scored["extra"] == ["payload[Joint2]"] and not scored["right"]


def test_a_quantization_counts_on_either_joint_and_a_cogging_needs_its_period() -> None:
    cogging = {"kind": "cogging", "joint": 1, "amplitude_nm": 0.2, "periods_per_rev": 12}
    truth = robot_zoo.answers(
        _robot({"kind": "quantization", "joint": None, "counts": 512}, cogging)
    )
    step = 2 * math.pi / 512
    found = [
        _found("quantization", "Joint2", step_rad=step * 1.1),
        _found("cogging", "Joint2", amplitude_nm=0.21, periods_per_rev=13),
    ]
    scored = robot_zoo.score(found, truth)
    assert scored["named"] == ["quantization"] and scored["missed"] == ["cogging[Joint2]"]


def test_the_generator_runs_a_robot_and_conceals_its_effect() -> None:
    """Two short runs with and without a torque offset on the elbow: the elbow's motion
    differs, the shoulder's command is what its controller computed."""
    plain = robot_zoo.simulate(_robot(), runs=2, duration_s=0.5)
    offset = robot_zoo.simulate(
        _robot({"kind": "torque_offset", "joint": 1, "offset_nm": 0.3}), runs=2, duration_s=0.5
    )
    assert set(plain[0]) >= {"time", "pos_meas1", "pos_meas2", "tau_con1", "tau_con2"}
    assert len(plain[0]["time"]) == 200  # 400 Hz
    assert np.max(np.abs(plain[0]["pos_meas2"] - offset[0]["pos_meas2"])) > 1e-3


def test_physics_no_candidate_describes_is_drawn_apart_and_changes_the_motion() -> None:
    """``make --model-error``: the robot of a seed is the same with it, plus the unmodelled
    physics (load-dependent friction, an elbow cable), which moves it differently."""
    plain, with_error = robot_zoo.draw(7), robot_zoo.draw(7, model_error=True)
    assert {k: v for k, v in with_error.items() if k != "unmodelled"} == plain
    assert set(with_error["unmodelled"]) == {"load_friction", "cable_nm_per_rad", "cable_rest_rad"}
    robot = _robot()
    moved = robot_zoo.simulate(robot, runs=2, duration_s=0.5)
    robot["unmodelled"] = with_error["unmodelled"]
    cabled = robot_zoo.simulate(robot, runs=2, duration_s=0.5)
    assert np.max(np.abs(moved[0]["pos_meas2"] - cabled[0]["pos_meas2"])) > 1e-3
    # neither required nor allowed: whatever the tool names for it is a false finding
    truth = robot_zoo.answers(robot)
    assert not any("cable" in k or "load" in k for k in [*truth["required"], *truth["allowed"]])
