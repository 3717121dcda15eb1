"""Parameters as users type them, through the real executables: a choice the node does not know,
a misspelt name, a value of the wrong type is one line and status 2 before anything is opened
(a node that would command a motor never starts on it); an integer for a double is the double."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

rclpy = pytest.importorskip("rclpy")
from rcl_interfaces.msg import ParameterType  # noqa: E402
from rcl_interfaces.srv import GetParameters  # noqa: E402
from rclpy.context import Context  # noqa: E402
from rclpy.exceptions import InvalidHandle  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402

from test.ros.conftest import Spinner, wait_for  # noqa: E402
from test.ros.test_actuator_driver import make_probe  # noqa: E402
from transparency_ros.core.errors import ConfigError  # noqa: E402
from transparency_ros.ros import estimator_params, feel_cage_behavior  # noqa: E402
from transparency_ros.ros.actuator_driver import PARAMETERS as DRIVER  # noqa: E402
from transparency_ros.ros.actuator_driver.node import ActuatorDriverNode  # noqa: E402
from transparency_ros.ros.contact_estimator import ContactEstimatorNode  # noqa: E402
from transparency_ros.ros.params import ParamSpec  # noqa: E402

pytestmark = pytest.mark.ros
BIN = Path(sys.executable).parent


def run_all(commands: list[list[str]], timeout_s: float = 60.0) -> list[tuple[int, str, str]]:
    """Start every command at once (each is a whole rclpy start-up), then collect them."""
    procs = [
        subprocess.Popen(
            cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=dict(os.environ)
        )
        for cmd in commands
    ]
    results = []
    for proc in procs:
        try:
            out, err = proc.communicate(timeout=timeout_s)
        finally:
            if proc.poll() is None:
                proc.kill()
        results.append((proc.returncode, out, err))
    return results


def choice_specs() -> list[tuple[str, ParamSpec]]:
    return (
        [("actuator_driver", s) for s in DRIVER if s.choices]
        + [("contact_estimator", s) for s in estimator_params.PARAMETERS if s.choices]
        + [("feel_cage_behavior", s) for s in feel_cage_behavior.parameters() if s.choices]
    )


def test_every_choice_parameter_refuses_a_value_it_does_not_know() -> None:
    """protocol:=MIT once sent moteus frames; now no choice maps 'anything else' to a default."""
    cases = choice_specs()
    assert {spec.name for _, spec in cases} >= {
        "protocol", "fault_policy", "sim_actuator", "sim_environment", "sim_ball",
        "timeout_action", "method", "actuator",
    }  # fmt: skip
    bad = [spec.choices[0].upper() + "x" for _, spec in cases]
    commands = [
        [str(BIN / exe), "--ros-args", "-p", f"{spec.name}:={value}"]
        for (exe, spec), value in zip(cases, bad, strict=True)
    ]
    results = run_all(commands)
    for (exe, spec), value, (code, out, err) in zip(cases, bad, results, strict=True):
        assert code == 2, (exe, spec.name, out, err)
        lines = err.strip().splitlines()
        assert len(lines) == 1, (exe, spec.name, err)
        assert spec.name in lines[0] and repr(value) in lines[0], lines[0]
        assert all(repr(choice) in lines[0] for choice in spec.choices), lines[0]
        assert "configured" not in out and "active" not in out, (exe, out)


def test_descriptors_list_the_choices() -> None:
    for _, spec in choice_specs():
        assert all(c in spec.descriptor().additional_constraints for c in spec.choices)


def test_misspelt_names_and_wrong_types_are_one_line() -> None:
    driver, estimator = str(BIN / "actuator_driver"), str(BIN / "contact_estimator")
    behavior = str(BIN / "feel_cage_behavior")
    results = run_all([
        [driver, "--ros-args", "-p", "torque_limt_nm:=1.0"],
        [behavior, "--ros-args", "-p", "budgett_s:=1.0"],
        [driver, "--ros-args", "-p", "motor_id:=abc"],
        [driver, "--ros-args", "-p", "k_s:=5000"],
    ])  # fmt: skip
    expected = [
        "unknown parameter(s) ['torque_limt_nm']",
        "unknown parameter(s) ['budgett_s']",
        "parameter motor_id: got 'abc' (string), expected an integer in [0, 2047]",
        "parameter k_s: got 5000.0 (double), expected a number in [0, 1000]",
    ]
    for (code, out, err), text in zip(results, expected, strict=True):
        assert code == 2, (text, out, err)
        assert len(err.strip().splitlines()) == 1 and text in err, err
        assert "active:" not in out, out
    # the estimator commands nothing: it runs on and says so
    proc = subprocess.Popen(
        [estimator, "--ros-args", "-p", "bogus_name:=1", "-p", "calibration_file:=c.yaml"],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=dict(os.environ),
    )  # fmt: skip
    try:
        out, _ = proc.communicate(timeout=5.0)
    except subprocess.TimeoutExpired:
        proc.terminate()
        out, _ = proc.communicate(timeout=10.0)
    assert "unknown parameter(s) ['bogus_name']" in out, out
    assert "calibration_file ignored: only method:=momentum_observer uses them" in out, out


def test_an_integer_for_a_double_is_taken_as_ros_users_type_it(ros_context: Context) -> None:
    """`-p k_s:=5 -p publish_rate_hz:=500` was a 24-line traceback; at runtime too."""
    exe = str(BIN / "actuator_driver")
    proc = subprocess.Popen(
        [exe, "--ros-args", "-p", "k_s:=5", "-p", "publish_rate_hz:=500", "-p",
         "channel:=int_for_double"],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=dict(os.environ),
    )  # fmt: skip
    probe = make_probe(ros_context)
    spinner = Spinner(ros_context, probe.node)
    try:
        assert wait_for(lambda: len(probe.states) > 20, 15.0), "no /joint_states"
        results = probe.set_params(k_d=1, torque_limit_nm=2)
        assert all(r.successful for r in results), results
        client = probe.node.create_client(GetParameters, "/actuator_driver/get_parameters")
        assert client.wait_for_service(timeout_sec=5.0)
        future = client.call_async(
            GetParameters.Request(names=["k_s", "publish_rate_hz", "k_d", "torque_limit_nm"])
        )
        assert wait_for(future.done, 5.0)
        values = future.result().values
        assert [v.type for v in values] == [ParameterType.PARAMETER_DOUBLE] * 4
        assert [v.double_value for v in values] == [5.0, 500.0, 1.0, 2.0]
    finally:
        proc.terminate()
        out, _ = proc.communicate(timeout=10.0)
        spinner.stop()
        probe.node.destroy_node()
    assert "Traceback" not in out, out


@pytest.mark.parametrize("make", ["estimator", "behavior", "driver"])
def test_a_refused_node_is_destroyed_before_the_error_leaves(
    ros_context: Context, make: str
) -> None:
    """A constructor that refuses a parameter after Node.__init__ has made the node undoes it:
    the half-built node (held here by the traceback) is destroyed, not left to the collector."""
    cls, bad = {
        "estimator": (ContactEstimatorNode, Parameter("method", value="no_such_method")),
        "behavior": (feel_cage_behavior.FeelCageBehaviorNode, Parameter("budgett_s", value=1.0)),
        "driver": (ActuatorDriverNode, Parameter("protocol", value="no_such_protocol")),
    }[make]
    with pytest.raises(ConfigError) as refused:
        cls(context=ros_context, parameter_overrides=[bad])
    built = [
        entry.frame.f_locals["self"]
        for entry in refused.traceback
        if isinstance(entry.frame.f_locals.get("self"), cls)
    ]
    assert built, "the traceback holds no half-built node"
    with pytest.raises(InvalidHandle):
        built[0].get_name()
