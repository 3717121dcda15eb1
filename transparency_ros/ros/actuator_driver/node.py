"""The lifecycle shell of ``actuator_driver``: transitions, the data path between ROS and the
hardware loop, services, and ``main``.

configure: open the bus (and start the simulated actuator when ``simulate``); activate: enter
motor mode and start the hardware loop; deactivate: zero torque, motor off; cleanup/shutdown:
close the bus. With ``autostart`` (default) the node configures and activates itself. Every exit
path (Ctrl-C, SIGTERM, an exception, lifecycle shutdown, interpreter exit) ends in
:meth:`ActuatorDriverNode.make_safe`: zero torque and motor mode off.
"""

from __future__ import annotations

import atexit
import contextlib
import sys
import threading
import time
from dataclasses import replace
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.msg import SetParametersResult
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState
from std_srvs.srv import SetBool, Trigger

from transparency_ros.canbus.client import ActuatorClient, BusSettings
from transparency_ros.canbus.clock import ClockOffset
from transparency_ros.canbus.loop import ControlLoop
from transparency_ros.canbus.multi import Motor, MultiControlLoop, RobotSample
from transparency_ros.canbus.protocol import (
    ActuatorProtocol,
    Feedback,
)
from transparency_ros.canbus.sim_device import SimulatedActuator
from transparency_ros.canbus.sim_robot import SimulatedBus, SimulatedBuses
from transparency_ros.core.cdr import JointStateReader
from transparency_ros.core.driver import (
    DriverCore,
    DriverSettings,
    SettingsError,
)
from transparency_ros.core.errors import TransparencyError
from transparency_ros.core.gc_pauses import GcPauses
from transparency_ros.ros import in_process
from transparency_ros.ros.actuator_driver.commands import CommandInput
from transparency_ros.ros.actuator_driver.diagnostics import (
    driver_status,
    gc_values,
    late_message,
    robot_statuses,
)
from transparency_ros.ros.actuator_driver.hardware import (
    MotorSpec,
    gain_error,
    make_protocol,
    motor_specs,
    start_simulated_buses,
    start_simulation,
)
from transparency_ros.ros.actuator_driver.messages import encode_setpoints, encode_states
from transparency_ros.ros.actuator_driver.parameters import (
    NODE_NAME,
    PARAMETERS,
    RUNTIME,
    declare_all,
    exit_logger,
    settings_value,
)
from transparency_ros.ros.hot_path import HotPath
from transparency_ros.ros.params import choice_error, destroyed_if_refused
from transparency_ros.ros.sim_ball import SimBallInterface
from transparency_ros.ros.sim_rig import SimRigInterface
from transparency_ros.ros.throttle import ThrottledWarning


@destroyed_if_refused
class ActuatorDriverNode(CommandInput, LifecycleNode):
    """One CAN actuator as a lifecycle node: parameters (``parameters``), what it talks to
    (``hardware``), the ROS-free loop (``canbus.loop.ControlLoop``) fed with targets from
    /joint_commands and publishing /joint_states from its own thread, services, diagnostics
    (``diagnostics``). Every exit path ends in :meth:`make_safe`."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, **kwargs)
        self.joint_names: list[str] = []
        self.values = declare_all(self, self._joints_of)
        self.core = DriverCore(DriverSettings(**{
            field: settings_value(name, self.values[name]) for name, field in RUNTIME.items()
        }))  # fmt: skip
        if self.values["gil_switch_interval_s"] > 0:
            sys.setswitchinterval(self.values["gil_switch_interval_s"])
            self.get_logger().info(
                f"process thread switch interval set to {sys.getswitchinterval() * 1e6:.0f} us"
            )
        self.protocol: ActuatorProtocol | None = None
        self.client: ActuatorClient | None = None
        self.sim: SimulatedActuator | None = None
        self.loop: ControlLoop | MultiControlLoop | None = None
        # several motors (motor_ids): one core each, their specs, the simulated buses
        self.cores: list[DriverCore] = [self.core]
        self.specs: list[MotorSpec] = []
        self.sim_buses: list[SimulatedBus] = []
        self._sim_runner: SimulatedBuses | None = None
        self._joint_pub: Any = None
        self._setpoint_pub: Any = None
        self._command_sub: Any = None
        self._hot_path: HotPath | None = None  # serves /joint_commands while configured
        self._safe_lock = threading.Lock()
        # time.monotonic() -> this node's ROS time, measured robustly (canbus/clock.py)
        self._to_ros = ClockOffset(lambda: self.get_clock().now().nanoseconds * 1e-9)
        self._warn_throttled = ThrottledWarning(self.get_logger())
        self._fault_reported = ""
        self.add_on_set_parameters_callback(self._validate_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)
        self._diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self._late_seen = (0, 0)  # (late replies, replies) at the last diagnostics
        self.gc_pauses = GcPauses().start()  # the collector's stalls, in /diagnostics
        self.create_timer(self.values["diagnostics_period_s"], self.publish_diagnostics)
        self.create_service(Trigger, "~/set_zero", self._on_set_zero)
        self.create_service(SetBool, "~/enable", self._on_enable)
        if self.values["simulate"] and self.values["sim_environment"] == "ball_on_rail":
            SimBallInterface(self, lambda: self.sim, self._ros_seconds_at)
        if self.values["simulate"] and self.values["sim_environment"] == "drop_rig":
            SimRigInterface(
                self, lambda: self.sim, self._ros_seconds_at,
                lambda: float(self.values["sim_drop_height_m"]),
            )  # fmt: skip
        atexit.register(self.make_safe)
        # A signal shuts the context down before spin() returns: stop the hardware loop at that
        # moment (it would otherwise publish on a dead context) and leave the motor disabled.
        self.context.on_shutdown(self._stop_and_disable)
        if self.values["autostart"]:
            self.trigger_configure()
            if self.configured:
                self.trigger_activate()

    def _joints_of(self, values: dict[str, Any]) -> list[str]:
        with contextlib.suppress(ValueError):  # a bad list is reported by configure
            self.joint_names = [spec.joint for spec in motor_specs(values)]
        return self.joint_names

    @property
    def configured(self) -> bool:
        return self.loop is not None

    # ----------------------------------------------------------------- parameters

    def _joint_param(self, name: str) -> tuple[str, str] | None:
        """(joint, runtime parameter) for a per-joint name such as "knee.k_s", else None."""
        joint, _, base = name.rpartition(".")
        return (joint, base) if joint in self.joint_names and base in RUNTIME else None

    def joint_settings(self, joint: str) -> DriverSettings:
        """A joint's driver settings from its per-joint parameters."""
        try:
            return replace(self.core.settings, **{
                field: settings_value(name, self.values[f"{joint}.{name}"])
                for name, field in RUNTIME.items()
            }).validated()  # fmt: skip
        except SettingsError as err:
            raise SettingsError(f"{joint}: {err}") from None

    def _validate_parameters(self, params: list[Parameter]) -> SetParametersResult:
        changes: dict[str | None, dict[str, Any]] = {}  # joint (None: all) -> settings changes
        for param in params:
            per_joint = self._joint_param(param.name)
            base = per_joint[1] if per_joint else param.name
            reason = choice_error(PARAMETERS, base, param.value)
            if reason:
                return SetParametersResult(successful=False, reason=reason)
            if param.name in RUNTIME and self.joint_names:
                return SetParametersResult(successful=False, reason=(
                    f"with motor_ids, {param.name} is set per joint: "
                    + ", ".join(f"{j}.{param.name}" for j in self.joint_names)))  # fmt: skip
            if base in RUNTIME:
                joint = per_joint[0] if per_joint else None
                changes.setdefault(joint, {})[RUNTIME[base]] = settings_value(base, param.value)
        for joint, change in changes.items():
            current = self.core.settings if joint is None else self._current_settings(joint)
            try:
                trial = replace(current, **change).validated()
            except (SettingsError, ValueError) as err:
                where = f"{joint}: " if joint else ""
                return SetParametersResult(successful=False, reason=where + str(err))
            reason = self._protocolgain_error(trial, joint)
            if reason:
                return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)

    def _current_settings(self, joint: str) -> DriverSettings:
        loop = self.loop
        if isinstance(loop, MultiControlLoop):
            return next(m.core.settings for m in loop.motors if m.name == joint)
        return self.joint_settings(joint)

    def _protocolgain_error(self, settings: DriverSettings, joint: str | None) -> str | None:
        protocols = (
            [m.protocol for m in self.loop.motors if m.name == joint or joint is None]
            if isinstance(self.loop, MultiControlLoop)
            else [self.protocol]
        )
        for proto in protocols:
            reason = gain_error(proto, settings)
            if reason:
                return reason
        return None

    # ----------------------------------------------------------------- lifecycle

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        try:
            self.specs = motor_specs(self.values)
        except ValueError as err:
            self.get_logger().error(f"configure failed: {err}")
            return TransitionCallbackReturn.FAILURE
        if self.specs:
            return self._configure_motors()
        return self._configure_one()

    def _configure_motors(self) -> TransitionCallbackReturn:
        """Several motors in one loop (``canbus.multi``): one bus per channel."""
        v = self.values
        buses: list[Any] = []
        try:
            pairs = [make_protocol({**v, "motor_id": s.motor_id}) for s in self.specs]
            protocols = [p for p, _ in pairs]
            fd = v["fd"] or protocols[0].is_fd
            if v["simulate"]:
                self._sim_runner = start_simulated_buses(v, self.specs, [d for _, d in pairs], fd)
                self.sim_buses = self._sim_runner.buses
            channels = list(dict.fromkeys(s.channel for s in self.specs))
            for channel in channels:
                buses.append(BusSettings(v["interface"], channel, v["bitrate"], fd).open())
        except (TransparencyError, ValueError) as err:
            self.get_logger().error(f"configure failed: {err}")
            for bus in buses:
                bus.shutdown()
            self._close()
            return TransitionCallbackReturn.FAILURE
        reason: str | None = None
        try:
            settings = [self.joint_settings(s.joint) for s in self.specs]
        except (SettingsError, ValueError) as err:
            settings, reason = [], f"{err}"
        else:
            reason = next(
                (f"{s.joint}: {r}" for s, p, c in zip(self.specs, protocols, settings, strict=True)
                 if (r := gain_error(p, c))), None)  # fmt: skip
        if reason:
            self.get_logger().error(f"configure failed: {reason}")
            for bus in buses:
                bus.shutdown()
            self._close()
            return TransitionCallbackReturn.FAILURE
        self.cores = [DriverCore(c) for c in settings]
        motors = [
            Motor(s.joint, p, core, bus=channels.index(s.channel))
            for s, p, core in zip(self.specs, protocols, self.cores, strict=True)
        ]
        self.loop = MultiControlLoop(
            buses,
            motors,
            rate_hz=v["publish_rate_hz"],
            reply_timeout_s=v["reply_timeout_s"],
            fault_policy=v["fault_policy"],
            on_sample=self._publish_robot_sample,
            on_fault=self._on_fault,
            on_error=self._on_loop_error,
        )
        self._create_topics()
        self.get_logger().info(
            f"configured: {len(motors)} {v['protocol']} motors "
            + ", ".join(f"{s.joint}=id {s.motor_id}@{s.channel}" for s in self.specs)
            + f" on {v['interface']}"
            + (f", simulated {v['sim_actuator']}s" if v["simulate"] else "")
        )
        return TransitionCallbackReturn.SUCCESS

    def _create_topics(self) -> None:
        self._joint_pub = self.create_lifecycle_publisher(JointState, "/joint_states", 10)
        if self.values["publish_setpoints"]:
            self._setpoint_pub = self.create_lifecycle_publisher(JointState, "/joint_setpoints", 10)
        # commands on a thread of their own, as raw bytes: through the executor, a torque
        # command took a median 5.6 ms (max 13.5) from the sender's stamp to the hardware loop
        # with three 1 kHz nodes on two cores, and 1.8 ms (max 3.1) this way (feel-cage cell)
        self._hot_path = HotPath(self)
        reader = JointStateReader()
        self._command_sub = self._hot_path.subscribe(
            JointState, "/joint_commands", 10, lambda data: self._on_command_bytes(reader, data)
        )
        self._hot_path.start()

    def _apply_parameters(self, params: list[Parameter]) -> None:
        for p in params:
            self.values[p.name] = p.value
        changes = {
            RUNTIME[p.name]: settings_value(p.name, p.value) for p in params if p.name in RUNTIME
        }
        lock = self.loop.lock if self.loop is not None else threading.RLock()
        with lock:
            if changes:
                self.core.update_settings(**changes)
            loop = self.loop
            for p in params:
                per_joint = self._joint_param(p.name)
                if per_joint and isinstance(loop, MultiControlLoop):
                    joint, base = per_joint
                    core = next(m.core for m in loop.motors if m.name == joint)
                    core.update_settings(**{RUNTIME[base]: settings_value(base, p.value)})
        if changes or any(self._joint_param(p.name) for p in params):
            self.get_logger().info(f"applied {', '.join(p.name for p in params)}")

    def _configure_one(self) -> TransitionCallbackReturn:
        v = self.values
        try:
            protocol, personality = make_protocol(v)
            settings = BusSettings(
                v["interface"], v["channel"], v["bitrate"], v["fd"] or protocol.is_fd
            )
            if v["simulate"]:
                self.sim = start_simulation(v, personality, settings)
            self.protocol = protocol
            self.client = ActuatorClient(protocol, settings.open())
        except (TransparencyError, ValueError) as err:
            self.get_logger().error(f"configure failed: {err}")
            self._close()
            return TransitionCallbackReturn.FAILURE
        reason = gain_error(protocol, self.core.settings)
        if reason:
            self.get_logger().error(f"configure failed: {reason}")
            self._close()
            return TransitionCallbackReturn.FAILURE
        self.loop = ControlLoop(
            self.client,
            self.core,
            rate_hz=v["publish_rate_hz"],
            reply_timeout_s=v["reply_timeout_s"],
            on_sample=self._publish_sample,
            on_fault=self._on_fault,
            on_error=self._on_loop_error,
        )
        self._create_topics()
        self.get_logger().info(
            f"configured: {v['protocol']} id {v['motor_id']} on {v['interface']}:{v['channel']}"
            + (f" with simulated {v['sim_actuator']}" if v["simulate"] else "")
        )
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        assert self.loop is not None
        silent = self._enable()
        if silent:
            self.get_logger().error(f"activate failed: no answer to enable from {silent}")
            self._disable()
            return TransitionCallbackReturn.FAILURE
        self.loop.start()
        motors = "motor" if isinstance(self.loop, ControlLoop) else f"{len(self.cores)} motors"
        self.get_logger().info(f"active: {motors} enabled, loop running")
        return super().on_activate(state)

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._stop_and_disable()
        self.get_logger().info("inactive: zero torque, motor mode off")
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._close()
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.make_safe()
        return TransitionCallbackReturn.SUCCESS

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.make_safe()
        return TransitionCallbackReturn.SUCCESS

    def _enable(self) -> str:
        """Enable the motor(s); the ones that did not answer, or ''."""
        loop = self.loop
        if isinstance(loop, MultiControlLoop):
            return ", ".join(loop.enable())
        assert loop is not None
        return "" if loop.enable() is not None else self.values["joint_name"]

    def _disable(self) -> str:
        """Disable the motor(s); the ones that did not answer, or ''. (A motor that did not
        answer was sent the frames; whether it took them is unknown: said in the log.)"""
        loop = self.loop
        if loop is None:
            return ""
        if isinstance(loop, MultiControlLoop):
            silent = ", ".join(loop.disable())
        else:
            silent = "" if loop.disable() else self.values["joint_name"]
        if silent:
            self.get_logger().warning(
                f"disable sent, no answer from {silent}: whether it took it is unknown "
                "(check the motor; its own watchdog is the last line)"
            )
        return silent

    def _stop_and_disable(self) -> None:
        if self.loop is not None:
            self.loop.stop()
            self._disable()

    def _close(self) -> None:
        self._stop_and_disable()
        if self._hot_path is not None and self._hot_path.stop():
            self._hot_path = None
        if self._command_sub is not None and self._hot_path is None:
            self.destroy_subscription(self._command_sub)
            self._command_sub = None
        for pub in (self._joint_pub, self._setpoint_pub):
            if pub is not None:
                self.destroy_lifecycle_publisher(pub)
        self._joint_pub = self._setpoint_pub = None
        if isinstance(self.loop, MultiControlLoop):
            self.loop.close()
        if self.client is not None:
            self.client.close()
            self.client = None
            self.protocol = None
        if self._sim_runner is not None:
            time.sleep(0.01)
            self._sim_runner.stop()
            self._sim_runner = None
            left = [p.is_enabled() for sim in self.sim_buses for p in sim.personalities]
            exit_logger().info(f"simulated motors enabled at exit: {sum(left)} of {len(left)}")
            self.sim_buses = []
        if self.sim is not None:
            time.sleep(0.01)  # let the device take the last frames
            self.sim.stop()
            seen = ", ".join(f"{k}={v}" for k, v in sorted(self.sim.events.items()))
            driven = self.sim.personality.is_enabled()
            exit_logger().info(f"simulated actuator saw: {seen}; motor enabled at exit: {driven}")
            self.sim = None
        self.loop = None

    def make_safe(self) -> None:
        """Zero torque, motor off, bus closed. Idempotent; called on every exit path."""
        with self._safe_lock:
            self._close()

    def destroy_node(self) -> None:
        self.gc_pauses.stop()
        if self._hot_path is not None and not self._hot_path.stop():
            exit_logger().error("command thread still running: node left undestroyed")
            return
        super().destroy_node()

    # ----------------------------------------------------------------- data path

    def _ros_seconds_at(self, monotonic_s: float) -> float:
        """A time.monotonic() instant on this node's ROS clock."""
        return self._to_ros(monotonic_s)

    def _publish_sample(self, fb: Feedback, sampled_s: float, applied: Any) -> None:
        # stamped when the reply was on the bus (see canbus.loop), not when read or published
        self._publish_states(self._ros_seconds_at(sampled_s), [self.values["joint_name"]],
                             [fb], [applied])  # fmt: skip

    def _publish_states(self, stamp_s: float, names: list[str], feedback: Any, applied: Any
                        ) -> None:  # fmt: skip
        """Publish a sample and its setpoints (``messages``), the setpoints first (an estimator
        composed into this process then has them when the sample comes), from the hardware
        thread; a signal may shut the context down meanwhile (the loop is being stopped then,
        and the motors disabled): that sample is dropped quietly."""
        pub, setpoints = self._joint_pub, self._setpoint_pub
        if pub is None:
            return
        try:
            if setpoints is not None:
                data = encode_setpoints(stamp_s, names, applied)
                in_process.publish(setpoints, self.context, "/joint_setpoints", data)
            data = encode_states(stamp_s, names, feedback)
            in_process.publish(pub, self.context, "/joint_states", data)
        except _rclpy.RCLError:
            if self.context.ok():
                raise

    def _publish_robot_sample(self, sample: RobotSample) -> None:
        loop = self.loop
        if isinstance(loop, MultiControlLoop):
            names = [loop.motors[i].name for i in sample.indices]
            stamp_s = self._ros_seconds_at(sample.stamp_s)
            self._publish_states(stamp_s, names, sample.feedback, sample.commands)

    def _on_fault(self, reason: str) -> None:
        self.get_logger().error(f"FAULT: {reason}; zero torque and motor off sent")
        self.publish_diagnostics()

    def _on_loop_error(self, err: BaseException) -> None:
        self.get_logger().error(f"hardware loop stopped by an error, motor disabled: {err!r}")
        self.publish_diagnostics()

    # ----------------------------------------------------------------- services

    def _on_set_zero(self, request: Trigger.Request, response: Trigger.Response) -> Any:
        loop = self.loop
        if loop is None:
            response.success, response.message = False, "not configured"
        elif isinstance(loop, MultiControlLoop):
            silent = loop.set_zero()
            response.success = not silent
            response.message = (
                f"no reply in the new frame from {silent} (driven ones are faulted and disabled)"
                if silent
                else "positions are now zero"
            )
        else:
            response.success = loop.set_zero()
            response.message = (
                "position is now zero"
                if response.success
                else "no reply in the new frame (if driven, faulted and disabled)"
            )
        return response

    def _on_enable(self, request: SetBool.Request, response: SetBool.Response) -> Any:
        loop = self.loop
        if loop is None:
            response.success, response.message = False, "not configured"
        elif request.data:
            silent = self._enable()
            response.success = not silent
            if response.success:
                loop.start()
            else:
                self._disable()
            response.message = "enabled" if response.success else f"no answer from {silent}"
        else:
            silent = self._disable()
            response.success = not silent
            response.message = (
                f"disable sent, no answer from {silent}"
                if silent
                else "zero torque, motor mode off"
            )
        self.publish_diagnostics()
        return response

    # ----------------------------------------------------------------- diagnostics

    def _late_in_period(self) -> str | None:
        """Late replies of this diagnostics period (diagnostics.late_message)."""
        if self.client is None:
            return None
        c = self.client.counters
        late, replies = c.late - self._late_seen[0], c.rx - self._late_seen[1]
        self._late_seen = (c.late, c.rx)
        return late_message(late, replies, self.values["reply_timeout_s"])

    def publish_diagnostics(self) -> None:
        loop = self.loop
        if isinstance(loop, MultiControlLoop):
            statuses = robot_statuses(self.values, loop, self.specs)
        else:
            statuses = [
                driver_status(self.values, self.core, self.client, loop, self._late_in_period)
            ]
        statuses[-1].values.extend(gc_values(self.gc_pauses))  # the loop's (or the motor's)
        array = DiagnosticArray(status=statuses)
        array.header.stamp = self.get_clock().now().to_msg()
        self._diag_pub.publish(array)
