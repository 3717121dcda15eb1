"""feel_cage_behavior, launch-free with real rclpy, driven through its topics and services."""

from __future__ import annotations

from typing import Any

import pytest

rclpy = pytest.importorskip("rclpy")
from diagnostic_msgs.msg import DiagnosticStatus  # noqa: E402
from geometry_msgs.msg import WrenchStamped  # noqa: E402
from rclpy.context import Context  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import DurabilityPolicy, QoSProfile  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import String  # noqa: E402
from std_srvs.srv import SetBool, Trigger  # noqa: E402

from test.ros.conftest import Spinner, wait_for  # noqa: E402
from transparency_ros.core.config import get_actuator  # noqa: E402
from transparency_ros.ros.feel_cage_behavior import FeelCageBehaviorNode  # noqa: E402

pytestmark = pytest.mark.ros


def call(node: Node, srv: Any, name: str, request: Any) -> Any:
    client = node.create_client(srv, name)
    assert client.wait_for_service(timeout_sec=5.0)
    future = client.call_async(request)
    assert wait_for(future.done, 5.0)
    return future.result()


def test_sweep_contact_act_caged(ros_context: Context) -> None:
    behavior = FeelCageBehaviorNode(
        context=ros_context,
        parameter_overrides=[
            Parameter("actuator", value="U10DD"),
            Parameter("command_rate_hz", value=200.0),
        ],
    )
    probe = Node("behavior_probe", context=ros_context)
    commands: list[JointState] = []
    phases: list[str] = []
    trials: list[DiagnosticStatus] = []
    latched = QoSProfile(depth=10, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    probe.create_subscription(JointState, "/joint_commands", commands.append, 100)
    probe.create_subscription(String, "/feel_cage/phase", lambda m: phases.append(m.data), latched)
    probe.create_subscription(DiagnosticStatus, "/feel_cage/trial", trials.append, latched)
    states = probe.create_publisher(JointState, "/joint_states", 10)
    contacts = probe.create_publisher(WrenchStamped, "/contact", 10)
    spinner = Spinner(ros_context, behavior, probe)
    try:

        def position(value: float) -> None:
            states.publish(JointState(name=["joint"], position=[value]))

        position(0.2)
        assert wait_for(lambda: behavior.position == pytest.approx(0.2))
        assert call(probe, Trigger, "/feel_cage_behavior/start", Trigger.Request()).success
        assert wait_for(lambda: len(commands) > 5)
        sweep = commands[-1]
        assert sweep.name == ["joint"] and sweep.velocity[0] == pytest.approx(6.283185, rel=1e-6)
        assert sweep.position[0] > 0.2
        # stamped with the time theta_d was computed for: every sweep command on one line
        # theta_d = c + theta_d' * stamp (the driver extrapolates from the stamp; a clock read
        # after computing put them 20-200 urad off it, and a preempted thread much more)
        first_ns = commands[0].header.stamp.sec * 10**9 + commands[0].header.stamp.nanosec
        lines = [
            m.position[0]
            - m.velocity[0]
            * (m.header.stamp.sec * 10**9 + m.header.stamp.nanosec - first_ns)
            * 1e-9
            for m in commands[:6]
        ]
        assert max(lines) - min(lines) < 1e-5, lines  # (float seconds since 1970: 0.24 us)
        # not armed: contacts are ignored
        contact = WrenchStamped()
        contact.header.frame_id = "joint"
        contact.header.stamp = behavior.get_clock().now().to_msg()
        contacts.publish(contact)
        assert not wait_for(lambda: phases[-1:] == ["process"], 0.3)
        assert call(probe, SetBool, "/feel_cage_behavior/arm", SetBool.Request(data=True)).success
        contact.header.stamp = behavior.get_clock().now().to_msg()
        contacts.publish(contact)
        torque = -get_actuator("U10DD").peak_torque_nm  # 10.5 V stall torque, peak-limited
        assert wait_for(lambda: bool(commands) and list(commands[-1].effort) == [torque])
        assert list(commands[-1].position) == []  # a pure torque command
        assert "act" in phases
        position(-1.6)  # past the cage angle (contact 0 rad - 90 degrees)
        assert wait_for(lambda: phases[-1:] == ["caged"])
        assert wait_for(lambda: bool(trials))
        values = {kv.key: kv.value for kv in trials[-1].values}
        assert trials[-1].message == "caged"
        assert float(values["t_process_s"]) >= 0.001
        assert float(values["t_act_s"]) > 0
        assert list(commands[-1].position) == [pytest.approx(-1.6)]  # holds the cage
    finally:
        spinner.stop()
        behavior.destroy_node()
        probe.destroy_node()


def test_undecodable_messages_are_skipped(ros_context: Context) -> None:
    """/joint_states and /contact arrive as raw bytes (a thread of their own): bytes that are
    no message of the type are skipped, and the node goes on with the next good one."""
    behavior = FeelCageBehaviorNode(context=ros_context)
    probe = Node("behavior_probe", context=ros_context)
    phases: list[str] = []
    latched = QoSProfile(depth=10, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    probe.create_subscription(String, "/feel_cage/phase", lambda m: phases.append(m.data), latched)
    states = probe.create_publisher(JointState, "/joint_states", 10)
    contacts = probe.create_publisher(WrenchStamped, "/contact", 10)
    spinner = Spinner(ros_context, behavior, probe)
    try:
        assert wait_for(
            lambda: states.get_subscription_count() > 0 and contacts.get_subscription_count() > 0
        )
        states.publish(b"\x00\x01\x00\x00\x07")
        states.publish(JointState(name=["joint"], position=[0.3]))
        assert wait_for(lambda: behavior.position == pytest.approx(0.3))
        assert call(probe, Trigger, "/feel_cage_behavior/start", Trigger.Request()).success
        assert call(probe, SetBool, "/feel_cage_behavior/arm", SetBool.Request(data=True)).success
        contacts.publish(b"\x00\x01\x00\x00\x07")
        assert not wait_for(lambda: phases[-1:] == ["process"], 0.3)
        contact = WrenchStamped()
        contact.header.frame_id = "joint"
        contact.header.stamp = behavior.get_clock().now().to_msg()
        contacts.publish(contact)
        assert wait_for(lambda: "process" in phases)
        assert behavior.hot_path.handler_errors == 0  # skipped on purpose, not crashed into
    finally:
        spinner.stop()
        behavior.destroy_node()
        probe.destroy_node()
