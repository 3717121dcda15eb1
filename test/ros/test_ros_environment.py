"""The ROS side of the environment: real rclpy + Fast DDS from the ros-jazzy wheels, confined to
loopback on this session's own domain (see test/conftest.py), each ``ros_context`` on its own."""

from __future__ import annotations

import os
import time

import pytest

rclpy = pytest.importorskip("rclpy")
from rclpy.context import Context  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.node import Node  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from transparency_ros import rosenv  # noqa: E402
from transparency_ros.rosenv import DOMAIN_MAX, DOMAIN_MIN, domain_ports  # noqa: E402

pytestmark = pytest.mark.ros


def test_session_is_confined_to_loopback_on_its_own_domain() -> None:
    assert os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    assert DOMAIN_MIN <= int(os.environ["ROS_DOMAIN_ID"]) <= DOMAIN_MAX
    assert "ROS_STATIC_PEERS" not in os.environ


def test_joint_state_round_trip_through_fast_dds() -> None:
    context = Context()
    rclpy.init(context=context)
    try:
        assert context.get_domain_id() == int(os.environ["ROS_DOMAIN_ID"])
        assert rclpy.get_rmw_implementation_identifier() == "rmw_fastrtps_cpp"
        node = Node("env_probe", context=context)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        received: list[JointState] = []
        node.create_subscription(JointState, "joint_states", received.append, 10)
        publisher = node.create_publisher(JointState, "joint_states", 10)
        deadline = time.monotonic() + 10.0
        sent = 0
        while len(received) < 5 and time.monotonic() < deadline:
            msg = JointState(name=["arm"], position=[0.1 * sent], velocity=[0.0], effort=[0.0])
            publisher.publish(msg)
            sent += 1
            executor.spin_once(timeout_sec=0.02)
        assert len(received) >= 5
        assert received[0].name == ["arm"]
        executor.shutdown()
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)


def test_each_test_context_is_on_a_domain_of_its_own_named_for_its_processes(
    ros_context: Context,
) -> None:
    domain = ros_context.get_domain_id()
    assert DOMAIN_MIN <= domain <= DOMAIN_MAX
    # processes the test starts with os.environ join the same domain
    assert int(os.environ["ROS_DOMAIN_ID"]) == domain


def test_a_participant_on_loopback_binds_ports_of_its_domain_that_the_pick_sees(
    ros_context: Context,
) -> None:
    """What makes a domain taken for :func:`pick_domain_id`: confined to loopback, Fast DDS
    binds unicast ports of the domain's range (7410 + 250 d and up), not its multicast
    discovery port 7400 + 250 d, which the pick once looked at alone."""
    domain = ros_context.get_domain_id()
    node = Node("port_probe", context=ros_context)
    try:
        bound = rosenv._bound_udp_ports() & set(domain_ports(domain))
        assert bound, f"no UDP port of domain {domain} bound by a live participant"
        assert domain_ports(domain).start not in bound
    finally:
        node.destroy_node()
