"""The parameter table of ``actuator_driver``: names, defaults, ranges, descriptions, which ones
apply at runtime (``RUNTIME``: parameter -> ``core.driver.DriverSettings`` field). The node
declares them from here, ``--help`` prints them, and the docs and config/actuator_driver.yaml are
generated from and tested against them."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import Any

from transparency_ros.canbus.protocol import PROTOCOLS
from transparency_ros.core.driver import TimeoutAction
from transparency_ros.ros.params import (
    ParamSpec,
    accept_integers_for_doubles,
    check_unknown,
    declare,
)

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
    P(
        "motor_ids",
        [-1],
        "several motors in one loop: their ids (one /joint_states with all of them; per-motor "
        "watchdogs); [-1]: the one motor of motor_id and joint_name",
        read_only=True,
    ),
    P(
        "joint_names",
        [""],
        "with motor_ids: one joint name per motor ([''] : joint_<id>)",
        read_only=True,
    ),
    P(
        "channels",
        [""],
        "with motor_ids: the bus channel of each motor ([''] : all on channel); every bus "
        "speaks the one protocol",
        read_only=True,
    ),
    P(
        "fault_policy",
        "all",
        "with motor_ids: when one motor faults, disable all motors or only that motor",
        read_only=True,
        choices=("all", "motor"),
    ),
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
        "wait for a reply per cycle [s] (capped at 0.9 period); with motor_ids, per motor of "
        "the busiest bus",
        read_only=True,
        low=1e-5,
        high=1.0,
    ),
    P(
        "publish_setpoints",
        True,
        "publish /joint_setpoints: the setpoint each motor followed, stamped like its "
        "/joint_states sample (the estimator computes tau_hat against it)",
        read_only=True,
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
    P(
        "reply_silence_s",
        0.1,
        "reply watchdog: FAULT (motor disabled, still polled and published) when a driven motor "
        "has not answered for this long, over at least half the requests sent in that time (a "
        "stall of this computer is not a silent motor)",
        low=0.005,
        high=10.0,
    ),
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
    "reply_silence_s": "reply_silence_s",
    "position_min_rad": "position_min_rad",
    "position_max_rad": "position_max_rad",
    "velocity_limit_rad_s": "velocity_limit_rad_s",
    "torque_limit_nm": "torque_limit_nm",
}


# parameters of earlier releases: refused at start with what replaced them
RENAMED = {
    "max_missed_replies": "reply_silence_s (the reply watchdog counts time now, not cycles)",
}


def settings_value(name: str, value: Any) -> Any:
    return TimeoutAction(value) if name == "timeout_action" else value


DESCRIPTION = (
    "Drive one CAN actuator (MIT mode, ODrive CANSimple or moteus), or several with motor_ids, "
    "and publish their state on /joint_states; follow /joint_commands with an impedance law. "
    "Lifecycle node; with "
    "autostart it configures and activates itself. Services: ~/set_zero (std_srvs/Trigger), "
    "~/enable (std_srvs/SetBool). Default: a simulated U10DD on a virtual bus."
)


def declare_all(node: Any, joints: Callable[[dict[str, Any]], list[str]]) -> dict[str, Any]:
    """Declare the table on ``node``, then every runtime parameter per joint ("<joint>.k_s",
    default: the global one) for the joints ``joints(values)`` names; refuse a name the node
    does not know (a misspelt one would leave a default in force on a motor); take integers for
    doubles at runtime. Returns the values."""
    values = declare(node, PARAMETERS)
    specs = list(PARAMETERS)
    for joint in joints(values):
        per_joint = [
            replace(spec, name=f"{joint}.{spec.name}", default=values[spec.name],
                    description=f"{joint}: {spec.description}")
            for spec in PARAMETERS if spec.name in RUNTIME
        ]  # fmt: skip
        values.update(declare(node, per_joint))
        specs += per_joint
    check_unknown(node, refuse=True, renamed=RENAMED)
    accept_integers_for_doubles(node, specs)
    return values


def exit_logger() -> Any:
    """A logger for the last words: the node's own also publishes to /rosout, which is gone
    once a signal has shut the context down (rcl then prints "Failed to publish log message to
    rosout")."""
    import rclpy.logging  # noqa: PLC0415 - the parameter table itself needs no rclpy

    return rclpy.logging.get_logger(f"{NODE_NAME}.exit")
