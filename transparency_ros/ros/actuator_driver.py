"""Lifecycle node ``actuator_driver``: a CAN actuator as sensor_msgs/JointState.

configure: open the bus (and start the simulated actuator when ``simulate``); activate: enter
motor mode and start the hardware loop; deactivate: zero torque, motor off; cleanup/shutdown:
close the bus. With ``autostart`` (default) the node configures and activates itself. Every exit
path (Ctrl-C, SIGTERM, an exception, lifecycle shutdown, interpreter exit) ends in
:meth:`ActuatorDriverNode.make_safe`: zero torque and motor mode off.

The loop itself, the watchdogs and limits are ROS-free (``canbus.loop``, ``core.driver``);
this file converts messages and parameters.
"""

from __future__ import annotations

import atexit
import math
import sys
import threading
import time
from dataclasses import replace
from typing import Any

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import SetParametersResult
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from rclpy.parameter import Parameter
from rclpy.utilities import ok as context_ok
from rclpy.utilities import try_shutdown
from sensor_msgs.msg import JointState
from std_srvs.srv import SetBool, Trigger

from transparency_ros.canbus import mit
from transparency_ros.canbus.client import ActuatorClient, BusSettings
from transparency_ros.canbus.clock import ClockOffset
from transparency_ros.canbus.errors import BusError, CanProtocolError
from transparency_ros.canbus.loop import ControlLoop
from transparency_ros.canbus.protocol import (
    PROTOCOLS,
    ActuatorProtocol,
    Feedback,
    MitProtocol,
    MoteusProtocol,
    ODriveProtocol,
)
from transparency_ros.canbus.sim_device import (
    MitDevice,
    MoteusDevice,
    ODriveDevice,
    Personality,
    SimulatedActuator,
)
from transparency_ros.core.actuator_physics import ActuatorPhysics, Environment, PhysicsParams
from transparency_ros.core.ball_on_rail import BallOnRail
from transparency_ros.core.cdr import encode_joint_state
from transparency_ros.core.config import get_actuator, load_drop_test
from transparency_ros.core.driver import (
    CommandRejectedError,
    DriverCore,
    DriverMode,
    DriverSettings,
    SettingsError,
    TimeoutAction,
    parse_joint_command,
)
from transparency_ros.core.drop_rig import DropRig, RigParams
from transparency_ros.core.errors import TransparencyError
from transparency_ros.core.feel_cage_config import load_setup
from transparency_ros.ros import in_process
from transparency_ros.ros.conversions import s_to_ns, stamp_to_s
from transparency_ros.ros.params import ParamSpec, choice_error, declare, parse_node_cli
from transparency_ros.ros.sim_ball import SimBallInterface
from transparency_ros.ros.sim_rig import SimRigInterface

NODE_NAME = "actuator_driver"

P = ParamSpec
PARAMETERS: tuple[ParamSpec, ...] = (
    # bus and device: fixed for the node's lifetime
    P(
        "interface",
        "virtual",
        "python-can interface: socketcan, pcan, kvaser, slcan, gs_usb, virtual, ...",
        read_only=True,
    ),
    P(
        "channel",
        "transparency_sim",
        "python-can channel (can0, PCAN_USBBUS1, /dev/ttyACM0, ...)",
        read_only=True,
    ),
    P(
        "bitrate",
        1_000_000,
        "nominal bitrate [bit/s] (ignored by virtual and socketcan)",
        read_only=True,
        low=10_000,
        high=1_000_000,
    ),
    P("fd", False, "open the bus in CAN-FD mode (moteus needs it)", read_only=True),
    P("protocol", "mit", "wire protocol", read_only=True, choices=PROTOCOLS),
    P(
        "motor_id",
        1,
        "MIT motor id / ODrive node id / moteus id",
        read_only=True,
        low=0,
        high=0x7FF,
    ),
    P(
        "gear_ratio",
        1.0,
        "device native units per output unit (1: device reports at the output)",
        read_only=True,
        low=1e-3,
        high=1e3,
    ),
    P("joint_name", "joint", "name in JointState messages", read_only=True),
    P("simulate", True, "attach the simulated actuator to the (virtual) bus", read_only=True),
    P(
        "sim_actuator",
        "U10DD",
        "Table 1 actuator the simulation integrates",
        read_only=True,
        choices=("U10DD", "EC60", "T2822", "U10GB"),
    ),
    P(
        "sim_encoder_counts_per_rev",
        16384,
        "simulated encoder counts per motor revolution",
        read_only=True,
        low=16,
        high=1 << 24,
    ),
    P(
        "sim_environment",
        "free",
        "what the simulated output drives: free, the feel-cage ball_on_rail (arm, rail and "
        "ball of config/feel_cage.yaml) or the drop-test drop_rig (arm and falling shuttle)",
        read_only=True,
        choices=("free", "ball_on_rail", "drop_rig"),
    ),
    P(
        "sim_shuttle_mass_kg",
        0.0,
        "drop_rig: shuttle mass [kg] (0: the paper's for sim_actuator, config/drop_test.yaml)",
        read_only=True,
        low=0.0,
        high=20.0,
    ),
    P(
        "sim_drop_height_m",
        0.1,
        "drop_rig: height of the shuttle's face above the arm tip for the next ~/sim/drop [m]",
        low=0.001,
        high=2.0,
    ),
    P(
        "sim_rig_seed",
        0,
        "drop_rig: seed of the DAQ sensor noise",
        read_only=True,
        low=0,
        high=2**31,
    ),
    P(
        "sim_ball",
        "rubber",
        "ball on the rail (ball_on_rail)",
        read_only=True,
        choices=("rubber", "lacrosse", "bocce"),
    ),
    P(
        "sim_place_ball",
        True,
        "ball_on_rail: ball on the rail from the start (false: place it "
        "later, e.g. after a settling sweep)",
        read_only=True,
    ),
    P(
        "sim_friction_ripple",
        0.0,
        "simulated position-dependent friction (fraction, once per output revolution)",
        read_only=True,
        low=0.0,
        high=0.5,
    ),
    P(
        "publish_rate_hz",
        1000.0,
        "loop and /joint_states rate [Hz]",
        read_only=True,
        low=1.0,
        high=10_000.0,
    ),
    P(
        "reply_timeout_s",
        0.0005,
        "wait for a reply per cycle [s] (capped at 0.9 period)",
        read_only=True,
        low=1e-5,
        high=1.0,
    ),
    P("autostart", True, "configure and activate on start", read_only=True),
    P(
        "gil_switch_interval_s",
        1e-4,
        "Python's thread switch interval for this process (the "
        "hardware loop waits up to this long for the interpreter; Python's default 5 ms stalls it "
        "behind busy executor threads); 0 leaves it unchanged",
        read_only=True,
        low=0.0,
        high=0.01,
    ),
    P("mit.p_min_rad", -12.5, "MIT position range min (firmware specific)", read_only=True),
    P("mit.p_max_rad", 12.5, "MIT position range max", read_only=True),
    P("mit.v_min_rad_s", -22.5, "MIT velocity range min", read_only=True),
    P("mit.v_max_rad_s", 22.5, "MIT velocity range max", read_only=True),
    P("mit.kp_min", 0.0, "MIT kp range min", read_only=True),
    P("mit.kp_max", 500.0, "MIT kp range max [N m/rad]", read_only=True),
    P("mit.kd_min", 0.0, "MIT kd range min", read_only=True),
    P("mit.kd_max", 5.0, "MIT kd range max [N m s/rad]", read_only=True),
    P("mit.t_min_nm", -12.0, "MIT torque range min", read_only=True),
    P("mit.t_max_nm", 12.0, "MIT torque range max", read_only=True),
    P(
        "moteus.kp_nm_per_rev",
        200.0,
        "servo.pid_position.kp configured in the moteus",
        read_only=True,
        low=1e-6,
        high=1e6,
    ),
    P(
        "moteus.kd_nms_per_rev",
        5.0,
        "servo.pid_position.kd configured in the moteus",
        read_only=True,
        low=1e-6,
        high=1e6,
    ),
    P(
        "moteus.watchdog_timeout_s",
        0.1,
        "moteus position-mode watchdog",
        read_only=True,
        low=1e-3,
        high=10.0,
    ),
    # runtime: validated, applied atomically
    P("k_s", 2.0, "virtual spring k_s [N m/rad]", low=0.0, high=1000.0),
    P("k_d", 0.0, "damping k_d [N m s/rad]", low=0.0, high=100.0),
    P(
        "command_timeout_s",
        0.5,
        "no /joint_commands for this long -> timeout_action",
        low=1e-3,
        high=60.0,
    ),
    P(
        "timeout_action",
        "hold",
        "after a command timeout: hold position or only damp",
        choices=("hold", "damp"),
    ),
    P("timeout_damping", 0.05, "k_d used by timeout_action=damp [N m s/rad]", low=0.0, high=100.0),
    P("max_missed_replies", 10, "replies missed in a row before FAULT", low=1, high=10_000),
    P("position_min_rad", -12.5, "command position clamp min [rad]"),
    P("position_max_rad", 12.5, "command position clamp max [rad]"),
    P("velocity_limit_rad_s", 20.0, "command velocity clamp [rad/s]", low=1e-3, high=1e4),
    P("torque_limit_nm", 5.0, "feed-forward torque clamp [N m]", low=1e-3, high=1e4),
    P("diagnostics_period_s", 1.0, "/diagnostics period [s]", read_only=True, low=0.01, high=60.0),
)

# parameter name -> DriverSettings field
RUNTIME = {
    "k_s": "k_s_nm_per_rad",
    "k_d": "k_d_nms_per_rad",
    "command_timeout_s": "command_timeout_s",
    "timeout_action": "timeout_action",
    "timeout_damping": "timeout_damping_nms_per_rad",
    "max_missed_replies": "max_missed_replies",
    "position_min_rad": "position_min_rad",
    "position_max_rad": "position_max_rad",
    "velocity_limit_rad_s": "velocity_limit_rad_s",
    "torque_limit_nm": "torque_limit_nm",
}


def _settings_value(name: str, value: Any) -> Any:
    return TimeoutAction(value) if name == "timeout_action" else value


class ActuatorDriverNode(LifecycleNode):
    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, **kwargs)
        self.values = declare(self, PARAMETERS)
        if self.values["gil_switch_interval_s"] > 0:
            sys.setswitchinterval(self.values["gil_switch_interval_s"])
            self.get_logger().info(
                f"process thread switch interval set to {sys.getswitchinterval() * 1e6:.0f} us"
            )
        self.core = DriverCore(DriverSettings(**{
            field: _settings_value(name, self.values[name]) for name, field in RUNTIME.items()
        }))  # fmt: skip
        self.protocol: ActuatorProtocol | None = None
        self.client: ActuatorClient | None = None
        self.sim: SimulatedActuator | None = None
        self.loop: ControlLoop | None = None
        self._joint_pub: Any = None
        self._command_sub: Any = None
        self._safe_lock = threading.Lock()
        # time.monotonic() -> this node's ROS time, measured robustly (canbus/clock.py)
        self._to_ros = ClockOffset(lambda: self.get_clock().now().nanoseconds * 1e-9)
        self._last_warn_s = -math.inf
        self._fault_reported = ""
        self.add_on_set_parameters_callback(self._validate_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)
        self._diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self._late_seen = (0, 0)  # (late replies, replies) at the last diagnostics
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

    @property
    def configured(self) -> bool:
        return self.client is not None and self.loop is not None

    # ----------------------------------------------------------------- parameters

    def _validate_parameters(self, params: list[Parameter]) -> SetParametersResult:
        changes = {}
        for param in params:
            reason = choice_error(PARAMETERS, param.name, param.value)
            if reason:
                return SetParametersResult(successful=False, reason=reason)
            if param.name in RUNTIME:
                changes[RUNTIME[param.name]] = _settings_value(param.name, param.value)
        try:
            trial = replace(self.core.settings, **changes).validated()
        except (SettingsError, ValueError) as err:
            return SetParametersResult(successful=False, reason=str(err))
        reason = self._protocol_gain_error(trial)
        if reason:
            return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)

    def _protocol_gain_error(self, settings: DriverSettings) -> str | None:
        proto = self.protocol
        if isinstance(proto, MitProtocol):
            kp = settings.k_s_nm_per_rad / proto.gear_ratio**2
            kd = settings.k_d_nms_per_rad / proto.gear_ratio**2
            if kp > proto.limits.kp_max or kd > proto.limits.kd_max:
                return (
                    f"k_s/k_d exceed the motor's MIT range kp <= {proto.limits.kp_max}, "
                    f"kd <= {proto.limits.kd_max}"
                )
        if isinstance(proto, MoteusProtocol) and proto.kp_scale(settings.k_s_nm_per_rad) > 1.0:
            return "k_s exceeds the moteus's configured kp (kp_scale would be > 1)"
        return None

    def _apply_parameters(self, params: list[Parameter]) -> None:
        for p in params:
            self.values[p.name] = p.value
        changes = {
            RUNTIME[p.name]: _settings_value(p.name, p.value) for p in params if p.name in RUNTIME
        }
        if changes:
            lock = self.loop.lock if self.loop is not None else threading.RLock()
            with lock:
                self.core.update_settings(**changes)
            self.get_logger().info(f"applied {', '.join(p.name for p in params)}")

    # ----------------------------------------------------------------- lifecycle

    def _make_protocol(self) -> tuple[ActuatorProtocol, Personality]:
        v = self.values
        g = v["gear_ratio"]
        if v["protocol"] == "mit":
            limits = mit.MitLimits(*(v[f"mit.{k}"] for k in (
                "p_min_rad", "p_max_rad", "v_min_rad_s", "v_max_rad_s", "kp_min", "kp_max",
                "kd_min", "kd_max", "t_min_nm", "t_max_nm")))  # fmt: skip
            return (
                MitProtocol(v["motor_id"], limits, gear_ratio=g),
                MitDevice(v["motor_id"], limits, gear_ratio=g),
            )
        if v["protocol"] == "odrive":
            return ODriveProtocol(v["motor_id"], gear_ratio=g), ODriveDevice(
                v["motor_id"], gear_ratio=g
            )
        kp, kd = v["moteus.kp_nm_per_rev"], v["moteus.kd_nms_per_rev"]
        return (
            MoteusProtocol(
                v["motor_id"],
                kp_nm_per_rev=kp,
                kd_nms_per_rev=kd,
                watchdog_timeout_s=v["moteus.watchdog_timeout_s"],
                gear_ratio=g,
            ),
            MoteusDevice(v["motor_id"], kp_nm_per_rev=kp, kd_nms_per_rev=kd, gear_ratio=g),
        )

    def _environment(self) -> Environment | None:
        v = self.values
        if v["sim_environment"] == "drop_rig":
            drop = load_drop_test()
            mass = v["sim_shuttle_mass_kg"] or drop.shuttle_mass_for(v["sim_actuator"])
            return DropRig(
                RigParams(
                    shuttle_mass_kg=mass,
                    arm_length_m=drop.arm_length_m,
                    arm_inertia_kgm2=drop.arm_inertia_kgm2,
                    seed=v["sim_rig_seed"],
                )
            )
        if v["sim_environment"] != "ball_on_rail":
            return None
        setup = load_setup()
        return BallOnRail(setup.balls[v["sim_ball"]], setup.geometry, placed=v["sim_place_ball"])

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        v = self.values
        try:
            protocol, personality = self._make_protocol()
            settings = BusSettings(
                v["interface"], v["channel"], v["bitrate"], v["fd"] or protocol.is_fd
            )
            if v["simulate"]:
                if v["interface"] != "virtual":
                    raise BusError(
                        "simulate:=true needs interface:=virtual (a real bus has a "
                        "real motor); set simulate:=false for hardware"
                    )
                actuator = get_actuator(v["sim_actuator"])
                physics = ActuatorPhysics(
                    PhysicsParams.from_actuator(
                        actuator,
                        encoder_counts_per_rev=v["sim_encoder_counts_per_rev"],
                        friction_ripple=v["sim_friction_ripple"],
                    ),
                    self._environment(),
                )
                self.sim = SimulatedActuator(physics, personality, settings).start()
            self.protocol = protocol
            self.client = ActuatorClient(protocol, settings.open())
        except (TransparencyError, ValueError) as err:
            self.get_logger().error(f"configure failed: {err}")
            self._close()
            return TransitionCallbackReturn.FAILURE
        reason = self._protocol_gain_error(self.core.settings)
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
        self._joint_pub = self.create_lifecycle_publisher(JointState, "/joint_states", 10)
        self._command_sub = self.create_subscription(
            JointState, "/joint_commands", self._on_command, 10
        )
        self.get_logger().info(
            f"configured: {v['protocol']} id {v['motor_id']} on {v['interface']}:{v['channel']}"
            + (f" with simulated {v['sim_actuator']}" if v["simulate"] else "")
        )
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        assert self.loop is not None
        if self.loop.enable() is None:
            self.get_logger().error("activate failed: the motor did not answer enable")
            self.loop.disable()
            return TransitionCallbackReturn.FAILURE
        self.loop.start()
        self.get_logger().info("active: motor enabled, loop running")
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

    def _stop_and_disable(self) -> None:
        if self.loop is not None:
            self.loop.stop()
            self.loop.disable()

    def _close(self) -> None:
        self._stop_and_disable()
        if self._command_sub is not None:
            self.destroy_subscription(self._command_sub)
            self._command_sub = None
        if self._joint_pub is not None:
            self.destroy_lifecycle_publisher(self._joint_pub)
            self._joint_pub = None
        if self.client is not None:
            self.client.close()
            self.client = None
            self.protocol = None
        if self.sim is not None:
            time.sleep(0.01)  # let the device take the last frames
            self.sim.stop()
            seen = ", ".join(f"{k}={v}" for k, v in sorted(self.sim.events.items()))
            driven = self.sim.personality.is_enabled()
            _exit_logger().info(f"simulated actuator saw: {seen}; motor enabled at exit: {driven}")
            self.sim = None
        self.loop = None

    def make_safe(self) -> None:
        """Zero torque, motor off, bus closed. Idempotent; called on every exit path."""
        with self._safe_lock:
            self._close()

    # ----------------------------------------------------------------- data path

    def _ros_seconds_at(self, monotonic_s: float) -> float:
        """A time.monotonic() instant on this node's ROS clock."""
        return self._to_ros(monotonic_s)

    def _publish_sample(self, fb: Feedback, sampled_s: float) -> None:
        pub = self._joint_pub
        if pub is None:
            return
        # when the reply was on the bus (see canbus.loop), not when read or published
        sec, nanosec = divmod(s_to_ns(self._ros_seconds_at(sampled_s)), 1_000_000_000)
        data = encode_joint_state(
            sec,
            nanosec,
            "",
            [self.values["joint_name"]],
            position=[fb.position_rad],
            velocity=[fb.velocity_rad_s],
            effort=[fb.torque_nm],
        )
        # serialized here (cheaper than rclpy's message objects), and handed directly to an
        # estimator composed into this process (ros.in_process)
        in_process.publish(pub, self.context, "/joint_states", data)

    def _on_command(self, msg: JointState) -> None:
        now = time.monotonic()
        stamp = stamp_to_s(msg.header.stamp)
        if stamp > 0:
            # a stamped command holds from its stamp on (streamed trajectories are extrapolated
            # from there, so transport latency does not make the joint lag)
            age = now - self._to_ros.back(stamp)
            if 0.0 <= age < 1.0:
                now -= age
        try:
            target = parse_joint_command(
                self.values["joint_name"], msg.name, msg.position, msg.velocity, msg.effort
            )
        except CommandRejectedError as err:
            with self._core_lock():
                self.core.reject(str(err))
            self._warn_throttled(f"rejected /joint_commands: {err}")
            return
        with self._core_lock():
            clamped = self.core.set_target(target, now)
        if clamped:
            self._warn_throttled("command clamped to the configured limits")

    def _core_lock(self) -> Any:
        return self.loop.lock if self.loop is not None else threading.RLock()

    def _warn_throttled(self, text: str, period_s: float = 1.0) -> None:
        now = time.monotonic()
        if now - self._last_warn_s >= period_s:
            self._last_warn_s = now
            self.get_logger().warning(text)

    def _on_fault(self, reason: str) -> None:
        self.get_logger().error(f"FAULT: {reason}; zero torque and motor off sent")
        self.publish_diagnostics()

    def _on_loop_error(self, err: BaseException) -> None:
        self.get_logger().error(f"hardware loop stopped by an error, motor disabled: {err!r}")
        self.publish_diagnostics()

    # ----------------------------------------------------------------- services

    def _on_set_zero(self, request: Trigger.Request, response: Trigger.Response) -> Any:
        if self.loop is None:
            response.success, response.message = False, "not configured"
        else:
            response.success = self.loop.set_zero()
            response.message = "position is now zero" if response.success else "no reply"
        return response

    def _on_enable(self, request: SetBool.Request, response: SetBool.Response) -> Any:
        loop = self.loop
        if loop is None:
            response.success, response.message = False, "not configured"
        elif request.data:
            response.success = loop.enable() is not None
            if response.success:
                loop.start()
            response.message = "enabled" if response.success else "the motor did not answer"
        else:
            loop.disable()
            response.success, response.message = True, "zero torque, motor mode off"
        self.publish_diagnostics()
        return response

    # ----------------------------------------------------------------- diagnostics

    def _late_in_period(self) -> str | None:
        """A warning when most replies of this diagnostics period came after the loop's wait.

        Late replies keep the reply watchdog content (the motor is alive), so a device that is
        persistently slower than ``reply_timeout_s`` runs on without a fault; this says so."""
        if self.client is None:
            return None
        c = self.client.counters
        late, replies = c.late - self._late_seen[0], c.rx - self._late_seen[1]
        self._late_seen = (c.late, c.rx)
        return _late_message(late, replies, self.values["reply_timeout_s"])

    def publish_diagnostics(self) -> None:
        status = DiagnosticStatus(
            name=f"{NODE_NAME}: {self.values['joint_name']}",
            hardware_id=f"{self.values['protocol']}:{self.values['motor_id']}",
        )
        s = self.core.status
        if s.mode is DriverMode.FAULT:
            status.level, status.message = DiagnosticStatus.ERROR, f"FAULT: {s.fault_reason}"
        elif self.client is None:
            status.level, status.message = DiagnosticStatus.WARN, "not configured"
        elif s.command_timed_out:
            status.level = DiagnosticStatus.WARN
            status.message = f"no command for {self.core.settings.command_timeout_s} s: "
            status.message += self.core.settings.timeout_action.value
        elif (late := self._late_in_period()) is not None:
            status.level, status.message = DiagnosticStatus.WARN, late
        else:
            status.level, status.message = DiagnosticStatus.OK, s.mode.value
        values: dict[str, Any] = {
            "mode": s.mode.value, "interface": self.values["interface"],
            "channel": self.values["channel"], "commands_accepted": s.commands_accepted,
            "commands_rejected": s.commands_rejected, "commands_clamped": s.commands_clamped,
            "missed_replies_total": s.missed_replies_total,
            "missed_replies_in_row": s.missed_replies_in_row, "last_rejection": s.last_rejection,
        }  # fmt: skip
        if self.client is not None:
            c = self.client.counters
            values.update(
                tx=c.tx,
                rx=c.rx,
                tx_errors=c.tx_errors,
                rx_errors=c.rx_errors,
                timeouts=s.missed_replies_total,
                late_replies=c.late,
                duplicate_replies=c.duplicates,
                malformed=c.malformed,
                other_frames=c.other,
                last_bus_error=c.last_error,
            )
        if self.loop is not None:
            st = self.loop.stats()
            values.update(
                loop_rate_hz=f"{st.rate_hz:.1f}",
                loop_cycles=st.cycles,
                overruns=st.overruns,
                jitter_p50_us=f"{st.jitter_p50_s * 1e6:.0f}",
                jitter_p99_us=f"{st.jitter_p99_s * 1e6:.0f}",
                jitter_max_us=f"{st.jitter_max_s * 1e6:.0f}",
            )
        status.values = [KeyValue(key=k, value=str(val)) for k, val in values.items()]
        array = DiagnosticArray(status=[status])
        array.header.stamp = self.get_clock().now().to_msg()
        self._diag_pub.publish(array)


def _exit_logger() -> Any:
    """A logger for the last words: the node's own also publishes to /rosout, which is gone
    once a signal has shut the context down (rcl then prints "Failed to publish log message to
    rosout")."""
    return rclpy.logging.get_logger(f"{NODE_NAME}.exit")


LATE_WARN_FRACTION = 0.5  # more of a period's replies late than this: WARN


def _late_message(late: int, replies: int, timeout_s: float) -> str | None:
    if replies <= 0 or late <= LATE_WARN_FRACTION * replies:
        return None
    return (
        f"{late} of {replies} replies late this period: the device or bus answers slower than "
        f"reply_timeout_s {timeout_s * 1e3:g} ms (samples are published at their bus time)"
    )


DESCRIPTION = (
    "Drive one CAN actuator (MIT mode, ODrive CANSimple or moteus) and publish its state on "
    "/joint_states; follow /joint_commands with an impedance law. Lifecycle node; with "
    "autostart it configures and activates itself. Services: ~/set_zero (std_srvs/Trigger), "
    "~/enable (std_srvs/SetBool). Default: a simulated U10DD on a virtual bus."
)


def main(args: list[str] | None = None) -> int:
    parse_node_cli(NODE_NAME, DESCRIPTION, PARAMETERS, args)
    rclpy.init(args=args)
    node: ActuatorDriverNode | None = None
    try:
        node = ActuatorDriverNode()
        executor = MultiThreadedExecutor(num_threads=2)
        executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except _rclpy.RCLError:
        # a signal can shut the context down while a MultiThreadedExecutor worker rebuilds its
        # wait set ("the given context is not valid"): that is the same shutdown, not a failure
        if context_ok():
            raise
    except (CanProtocolError, TransparencyError) as err:
        print(f"{NODE_NAME}: error: {err}", file=sys.stderr)  # noqa: T201
        return 2
    finally:
        if node is not None:
            node.make_safe()
            _exit_logger().info("shut down: motor disabled, bus closed")
            node.destroy_node()
        try_shutdown()
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
