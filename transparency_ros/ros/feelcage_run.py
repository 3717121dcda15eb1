"""EXPERIMENTAL: Table 2 through the real nodes (driver with the ball on the rail, estimator,
behavior). Not wired into the CLI: in one 2-core process the error signal carries 20-40 mrad of
scheduling noise against epsilon = 10 mrad, so the cells do not match yet (README, Status).

One cell: the three nodes run in this process (launch-free composition, each on its own
executor thread) and talk only through ROS topics, parameters and services. The procedure:
1. the behavior sweeps at 1 rev/s with no ball on the rail, the estimator's threshold out of
   reach; after ``settle_s`` e_s is measured from /estimated_effort over one revolution;
2. the estimator gets contact_onset = e_s + epsilon (parameters, set atomically), is reset, the
   ball is placed on the rail as soon as the arm is clear of it, and the behavior is armed;
3. the trial ends when the behavior reports caged/lost or the ball left the workspace.
Ground truth (when the arm first touched the ball, when the ball passed the exit) comes from the
simulator, converted from its monotonic clock to the ROS clock of the stamps.
"""

from __future__ import annotations

import itertools
import threading
import time
from collections import deque
from typing import Any

import rclpy
from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.utilities import try_shutdown
from sensor_msgs.msg import JointState
from std_srvs.srv import SetBool, Trigger

from transparency_ros.core import feel_cage as fc
from transparency_ros.core.ball_on_rail import BallOnRail
from transparency_ros.core.config import get_actuator
from transparency_ros.core.feel_cage_config import FeelCageSetup
from transparency_ros.ros.actuator_driver import ActuatorDriverNode
from transparency_ros.ros.contact_estimator import ContactEstimatorNode
from transparency_ros.ros.feel_cage_behavior import FeelCageBehaviorNode
from transparency_ros.rosenv import local_ros_env

_channels = itertools.count()


def _wait(condition: Any, timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.005)
    return bool(condition())


def _call(node: Node, srv: Any, name: str, request: Any) -> Any:
    client = node.create_client(srv, name)
    if not client.wait_for_service(timeout_sec=10.0):
        raise RuntimeError(f"{name} not available")
    future = client.call_async(request)
    if not _wait(future.done, 10.0):
        raise RuntimeError(f"{name} did not answer")
    return future.result()


def run_cell(actuator: str, ball: str, setup: FeelCageSetup, settle_s: float = 6.0
             ) -> fc.TrialRecord:  # fmt: skip
    import os  # noqa: PLC0415

    ros_env = local_ros_env()
    os.environ.update({k: ros_env[k] for k in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE")})
    context = Context()
    rclpy.init(context=context)
    peak = get_actuator(actuator).peak_torque_nm
    driver = ActuatorDriverNode(context=context, parameter_overrides=[
        Parameter(k, value=v) for k, v in {
            "protocol": "moteus", "channel": f"feelcage_{next(_channels)}",
            "sim_actuator": actuator, "sim_environment": "ball_on_rail", "sim_ball": ball,
            "sim_place_ball": False, "sim_friction_ripple": setup.friction_ripple,
            "k_s": setup.k_s_nm_per_rad, "publish_rate_hz": setup.sample_rate_hz,
            "position_min_rad": -1000.0, "position_max_rad": 1000.0,
            "velocity_limit_rad_s": 1000.0, "torque_limit_nm": peak, "command_timeout_s": 1.0,
            "moteus.kp_nm_per_rev": 200.0,
        }.items()])  # fmt: skip
    estimator = ContactEstimatorNode(
        context=context,
        parameter_overrides=[
            Parameter("k_s", value=setup.k_s_nm_per_rad),
            Parameter("contact_onset_rad", value=9.9),
            Parameter("contact_release_rad", value=9.8),
        ],
    )
    behavior = FeelCageBehaviorNode(
        context=context, parameter_overrides=[Parameter("actuator", value=actuator)]
    )
    probe = Node("feelcage_runner", context=context)
    errors: deque[float] = deque(maxlen=round(setup.sample_rate_hz))
    trial: list[DiagnosticStatus] = []

    def on_estimate(msg: JointState) -> None:
        errors.extend(msg.position)

    probe.create_subscription(JointState, "/estimated_effort", on_estimate, 1000)
    probe.create_subscription(DiagnosticStatus, "/feel_cage/trial", trial.append, 10)
    executors = []
    for node in (driver, estimator, behavior, probe):
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        thread = threading.Thread(target=executor.spin, daemon=True)
        thread.start()
        executors.append((executor, thread))
    try:
        if not _wait(lambda: behavior.position is not None, 10.0):
            raise RuntimeError("no /joint_states from the driver")
        if not _call(probe, Trigger, "/feel_cage_behavior/start", Trigger.Request()).success:
            raise RuntimeError("behavior did not start")
        time.sleep(settle_s)
        e_s = max(abs(e) for e in list(errors))
        eps = setup.epsilon_rad
        estimator.reconfigure(contact_onset_rad=e_s + eps, contact_release_rad=e_s + eps / 2)
        _call(probe, Trigger, "/contact_estimator/reset", Trigger.Request())
        sim = driver.sim
        assert sim is not None
        env = sim.physics.environment
        assert isinstance(env, BallOnRail)

        def place() -> bool:
            with sim.lock:
                return env.place(sim.physics.output_position_rad)

        if not _wait(place, 2.0):
            raise RuntimeError("could not place the ball")
        _call(probe, SetBool, "/feel_cage_behavior/arm", SetBool.Request(data=True))
        _wait(
            lambda: (
                bool(trial)
                or (env.state.exit_s is not None and behavior.state.phase in (fc.Phase.SWEEP,))
            ),
            3.0,
        )
        _wait(lambda: bool(trial), 0.5)
        # ground truth: simulator time -> monotonic -> ROS time
        offset = sim.start_monotonic_s + (time.time() - time.monotonic())
        contact = env.state.first_contact_s
        exit_s = env.state.exit_s
        contact_ros = contact + offset if contact is not None else None
        exit_ros = exit_s + offset if exit_s is not None else None
        state = behavior.state
        caged_in_time = (
            state.phase is fc.Phase.CAGED
            and state.done_s is not None
            and (exit_ros is None or state.done_s < exit_ros)
        )
        final = (
            state
            if caged_in_time or state.phase is not fc.Phase.CAGED
            else fc.BehaviorState(
                fc.Phase.LOST,
                state.start_s,
                state.start_position_rad,
                state.detected_s,
                state.act_start_s,
                state.done_s,
            )
        )
        return fc.record(final, contact_ros, exit_ros)
    finally:
        for executor, thread in executors:
            executor.shutdown(timeout_sec=10.0)
            thread.join(timeout=10.0)
        driver.make_safe()
        for node in (driver, estimator, behavior, probe):
            node.destroy_node()
        try_shutdown(context=context)
