"""Node ``feel_cage_behavior``: the feel -> process -> act state machine of Sec. 4.

A thin shell around ``core.feel_cage``. The transition function steps on every /joint_states
sample (the control rate is the driver's sample rate; the act phase ends on the first sample past
the cage angle) and on a timer at ``command_rate_hz`` (so the time budget runs out even without
samples). Commands go to /joint_commands when their kind changes and are refreshed at
``command_rate_hz``: sweep: stamped theta_d with theta_d' = 1 rev/s, which the driver extrapolates
between messages; act: a pure torque, the actuator's 10.5 V open-loop torque; caged: hold.
Streaming the sweep at a modest rate instead of once per sample leaves the CPU to the driver and
the estimator. /contact onsets are taken once the node is armed.

/joint_states and /contact are served as raw bytes on a thread of their own (``ros.hot_path``),
not by the executor, which keeps the services and the timer: a 1 kHz stream through rclpy's
executor cost this node 38 % of a core and delayed onsets by 7-13 ms (feel-cage cell, two cores);
this way 19 % and 3-10 ms. A message that does not decode is logged and skipped.

Interfaces (standard types only):
* ~/start (std_srvs/Trigger): sweep from the current position;
* ~/arm (std_srvs/SetBool): take /contact onsets (true) or ignore them (false, e.g. while the
  sweep settles and e_s is measured);
* /feel_cage/phase (std_msgs/String, latched): idle, sweep, process, act, caged, lost;
* /feel_cage/trial (diagnostic_msgs/DiagnosticStatus), at the end of a trial: message = phase,
  values detected_stamp_s (t_e), act_start_s, done_s, t_process_s, t_act_s.
"""

from __future__ import annotations

import math
import sys
import threading
from dataclasses import replace
from functools import cache
from typing import Any

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from geometry_msgs.msg import WrenchStamped
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile
from rclpy.serialization import deserialize_message
from rclpy.time import Time
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from std_srvs.srv import SetBool, Trigger

from transparency_ros.core import feel_cage as fc
from transparency_ros.core.cdr import CdrError, JointStateReader
from transparency_ros.core.config import get_actuator
from transparency_ros.core.errors import ConfigError
from transparency_ros.core.feel_cage_config import load_setup
from transparency_ros.ros.conversions import stamp_to_s
from transparency_ros.ros.hot_path import HotPath
from transparency_ros.ros.params import (
    ParamSpec,
    check_unknown,
    declare,
    destroyed_if_refused,
    run_node,
)
from transparency_ros.ros.throttle import ThrottledWarning

NODE_NAME = "feel_cage_behavior"
P = ParamSpec


@cache
def parameters() -> tuple[ParamSpec, ...]:
    """The parameter table; defaults of the geometry and task come from config/feel_cage.yaml,
    read on first use (not at import, so --help works and a bad file is a clear error)."""
    _SETUP = load_setup()  # noqa: N806
    return (
        P("joint_name", "joint", "joint in /joint_states and /joint_commands", read_only=True),
        P(
            "actuator",
            "U10DD",
            "Table 1 actuator: its motor model gives the act torque",
            read_only=True,
            choices=("U10DD", "EC60", "T2822", "U10GB"),
        ),
        P(
            "act_voltage_v",
            _SETUP.act_voltage_v,
            "open-loop voltage of the act phase [V]",
            read_only=True,
            low=0.1,
            high=48.0,
        ),
        P(
            "sweep_speed_rad_s",
            2.0 * math.pi,
            "CCW sweep speed [rad/s] (1 rev/s)",
            read_only=True,
            low=0.01,
            high=100.0,
        ),
        P(
            "contact_angle_rad",
            _SETUP.geometry.contact_angle_rad,
            "where the rail meets the tip's circle [rad]",
            read_only=True,
            low=-10.0,
            high=10.0,
        ),
        P(
            "cage_angle_rad",
            _SETUP.geometry.cage_angle_rad,
            "CW turn from the contact angle that cages the ball [rad]",
            read_only=True,
            low=0.01,
            high=6.3,
        ),
        P(
            "process_time_s",
            _SETUP.process_time_s,
            "t_process before acting [s]",
            read_only=True,
            low=0.0,
            high=1.0,
        ),
        P(
            "budget_s",
            10.0,
            "contact -> caged budget; past it the trial is lost [s]",
            read_only=True,
            low=0.001,
            high=1000.0,
        ),
        P(
            "command_rate_hz",
            50.0,
            "/joint_commands refresh rate [Hz]; the state machine steps on every /joint_states "
            "sample",
            read_only=True,
            low=1.0,
            high=5000.0,
        ),
    )


LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)


@destroyed_if_refused
class FeelCageBehaviorNode(Node):
    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, **kwargs)
        self.values = declare(self, parameters())
        check_unknown(self, refuse=True)  # it sends /joint_commands: refused at start
        actuator = get_actuator(self.values["actuator"])
        self.config = fc.FeelCageConfig(
            sweep_speed_rad_s=self.values["sweep_speed_rad_s"],
            act_torque_nm=fc.open_loop_torque_nm(actuator, -self.values["act_voltage_v"]),
            cage_position_rad=self.values["contact_angle_rad"] - self.values["cage_angle_rad"],
            process_time_s=self.values["process_time_s"],
            budget_s=self.values["budget_s"],
        )
        self.state = fc.BehaviorState()
        self.armed = False
        self.position: float | None = None
        self.position_s: float | None = None  # stamp of the sample (None: unstamped)
        self._last_command: fc.Command | None = None
        self._last_publish_s = -math.inf
        self._refresh_s = 1.0 / self.values["command_rate_hz"]
        self._commands = self.create_publisher(JointState, "/joint_commands", 10)
        self._phase_pub = self.create_publisher(String, "/feel_cage/phase", LATCHED)
        self._trial_pub = self.create_publisher(DiagnosticStatus, "/feel_cage/trial", LATCHED)
        self.lock = threading.Lock()  # the state, between the hot path and the executor
        self._reader = JointStateReader()
        self._warn = ThrottledWarning(self.get_logger())
        self.hot_path = HotPath(self)
        self.hot_path.subscribe(JointState, "/joint_states", 10, self._on_state_bytes)
        self.hot_path.subscribe(WrenchStamped, "/contact", 10, self._on_contact_bytes)
        self.create_service(Trigger, "~/start", self._on_start)
        self.create_service(SetBool, "~/arm", self._on_arm)
        self.create_timer(self._refresh_s, self._on_timer)
        self._publish_phase()
        self.hot_path.start()

    def destroy_node(self) -> None:
        if not self.hot_path.stop():
            self.get_logger().error("hot path thread still running: node left undestroyed")
            return
        super().destroy_node()

    def _on_timer(self) -> None:
        with self.lock:
            self._step()

    def _on_state_bytes(self, data: bytes) -> None:
        try:
            fields = self._reader(data)
        except CdrError as err:
            self._warn(f"/joint_states: undecodable message skipped: {err}")
            return
        name = self.values["joint_name"]
        index = fields.name.index(name) if name in fields.name else -1
        if 0 <= index < len(fields.position) and math.isfinite(fields.position[index]):
            with self.lock:
                self.position = fields.position[index]
                self.position_s = fields.stamp_ns * 1e-9 or None
                self._step()

    def _on_contact_bytes(self, data: bytes) -> None:
        try:
            msg = deserialize_message(data, WrenchStamped)
        except Exception as err:  # noqa: BLE001 - rclpy raises several kinds for bad bytes
            self._warn(f"/contact: undecodable message skipped: {err}")
            return
        with self.lock:
            self._on_contact(msg)

    def _now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _on_contact(self, msg: WrenchStamped) -> None:
        if not self.armed or msg.header.frame_id != self.values["joint_name"]:
            return
        before = self.state.phase
        stamp = stamp_to_s(msg.header.stamp)
        self.state = fc.on_contact(self.state, stamp)
        if before is fc.Phase.SWEEP and self.state.phase is fc.Phase.PROCESS:
            # the cage angle of the revolution in which the ball was felt
            position = self.position if self.position is not None else 0.0
            contact = self.values["contact_angle_rad"]
            turns = round((position - contact) / (2.0 * math.pi))
            self.config = replace(
                self.config,
                cage_position_rad=contact + 2.0 * math.pi * turns - self.values["cage_angle_rad"],
            )
            self._publish_phase()
            self._step()  # t_process counts from the onset stamp: it may be over already

    def _on_start(self, request: Trigger.Request, response: Trigger.Response) -> Any:
        with self.lock:
            if self.position is None:
                response.success, response.message = False, "no /joint_states yet"
                return response
            self.state = fc.start(self._now(), self.position)
            self._last_command = None
            self._publish_phase()
        response.success, response.message = True, "sweeping"
        return response

    def _on_arm(self, request: SetBool.Request, response: SetBool.Response) -> Any:
        with self.lock:
            self.armed = bool(request.data)
        response.success, response.message = True, "armed" if self.armed else "disarmed"
        return response

    def _step(self) -> None:
        if self.position is None or self.state.phase is fc.Phase.IDLE:
            return
        before = self.state.phase
        now = self._now()
        self.state, command = fc.step(
            self.state, self.config, now, self.position, position_s=self.position_s
        )
        if command is not None and (
            type(command) is not type(self._last_command)
            or now - self._last_publish_s >= self._refresh_s
        ):
            self._publish_command(command, now)
            self._last_command, self._last_publish_s = command, now
        if self.state.phase is not before:
            self._publish_phase()
            if self.state.phase in (fc.Phase.CAGED, fc.Phase.LOST):
                self._publish_trial()

    def _publish_command(self, command: fc.Command, now_s: float) -> None:
        """Stamped with the time theta_d was computed for (the driver extrapolates from the
        stamp: a later clock reading, after this thread was preempted, would put it behind)."""
        msg = JointState(name=[self.values["joint_name"]])
        msg.header.stamp = Time(nanoseconds=round(now_s * 1e9)).to_msg()
        if isinstance(command, fc.Sweep):
            msg.position, msg.velocity = [command.position_rad], [command.velocity_rad_s]
        elif isinstance(command, fc.Torque):
            msg.effort = [command.torque_nm]
        else:
            msg.position = [command.position_rad]
        self._commands.publish(msg)

    def _publish_phase(self) -> None:
        self._phase_pub.publish(String(data=self.state.phase.value))

    def _publish_trial(self) -> None:
        s = self.state
        values = {
            "detected_stamp_s": s.detected_s, "act_start_s": s.act_start_s, "done_s": s.done_s,
            "t_process_s": (s.act_start_s - s.detected_s
                            if s.act_start_s is not None and s.detected_s is not None else None),
            "t_act_s": (s.done_s - s.act_start_s
                        if s.done_s is not None and s.act_start_s is not None
                        and s.phase is fc.Phase.CAGED else None),
        }  # fmt: skip
        status = DiagnosticStatus(
            name=f"{NODE_NAME}: trial", message=s.phase.value, level=DiagnosticStatus.OK
        )
        status.values = [
            KeyValue(key=k, value="" if v is None else f"{v:.9f}") for k, v in values.items()
        ]
        self._trial_pub.publish(status)


DESCRIPTION = (
    "Feel -> process -> act (Sec. 4): sweep CCW at 1 rev/s, on a /contact onset wait t_process, "
    "then turn CW open loop at 10.5 V to the cage angle. Services ~/start, ~/arm; topics "
    "/feel_cage/phase, /feel_cage/trial."
)


def main(args: list[str] | None = None) -> int:
    try:
        specs = parameters()
    except ConfigError as err:
        print(f"{NODE_NAME}: error: {err}", file=sys.stderr)  # noqa: T201
        return 2
    return run_node(NODE_NAME, DESCRIPTION, specs, FeelCageBehaviorNode, args)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
