"""Demo step: the real `actuator_driver` process with the simulated actuator, seen through ROS.

Starts the executable as its own process (as `ros2 run` does), subscribes to /joint_states,
commands a step on /joint_commands, records the response, stops the process with SIGINT and
checks from its log that the simulated motor ended disabled.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from sensor_msgs.msg import JointState

from transparency_ros.ros.conversions import stamp_to_s
from transparency_ros.ros.harness import (
    Listener,
    driver_left_motor_enabled,
    start_node,
    stop_node,
)


@dataclass(frozen=True)
class DriverDemoResult:
    rate_hz: float
    samples: list[tuple[float, float, float, float]]  # t [s], position, velocity, effort
    target_rad: float
    final_position_rad: float
    motor_disabled_at_exit: bool
    log_tail: str


def run_driver_demo(
    protocol: str = "mit", actuator: str = "U10DD", target_rad: float = 1.0, seconds: float = 2.0
) -> DriverDemoResult:
    proc = start_node(
        "actuator_driver",
        {"protocol": protocol, "sim_actuator": actuator, "command_timeout_s": 60.0},
    )
    samples: list[tuple[float, float, float, float]] = []

    def on_state(msg: JointState) -> None:
        stamp = stamp_to_s(msg.header.stamp)
        samples.append((stamp, msg.position[0], msg.velocity[0], msg.effort[0]))

    log = ""
    try:
        with Listener("transparency_demo") as node:
            node.create_subscription(JointState, "/joint_states", on_state, 1000)
            commands = node.create_publisher(JointState, "/joint_commands", 10)
            deadline = time.monotonic() + 20.0
            while len(samples) < 200 and time.monotonic() < deadline:
                time.sleep(0.02)
            if not samples:
                raise RuntimeError("actuator_driver published no /joint_states within 20 s")
            start = len(samples)
            commands.publish(JointState(name=["joint"], position=[target_rad]))
            time.sleep(seconds)
            window = samples[start:]
    finally:
        log = stop_node(proc)
    rate = (len(window) - 1) / (window[-1][0] - window[0][0]) if len(window) > 1 else 0.0
    t0 = samples[start][0]
    trace = [(t - t0, p, v, e) for t, p, v, e in samples[max(0, start - 100) :]]
    disabled = bool(log) and driver_left_motor_enabled(log) is None
    tail = "\n".join(line for line in log.splitlines() if "rosout" not in line)[-800:]
    return DriverDemoResult(rate, trace, target_rad, samples[-1][1], disabled, tail)


def plot_step(result: DriverDemoResult, path: Path, title: str) -> Path:
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: PLC0415
    from matplotlib.figure import Figure  # noqa: PLC0415

    fig = Figure(figsize=(8, 5), layout="constrained")
    FigureCanvasAgg(fig)
    ax_p, ax_e = fig.subplots(2, 1, sharex=True)
    t = [s[0] * 1e3 for s in result.samples]
    ax_p.plot(t, [s[1] for s in result.samples], label="position θ_a (/joint_states)")
    ax_p.axhline(result.target_rad, color="0.5", ls="--", label="command θ_d")
    ax_e.plot(t, [s[3] for s in result.samples], color="C3", label="drive torque (effort)")
    ax_p.set(ylabel="position [rad]", title=title)
    ax_e.set(xlabel="time since the command [ms]", ylabel="torque [N·m]")
    for ax in (ax_p, ax_e):
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
    fig.savefig(path, dpi=110)
    return path
