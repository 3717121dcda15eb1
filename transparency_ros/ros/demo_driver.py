"""Demo step: the real `actuator_driver` process with the simulated actuator, seen through ROS.

Starts the executable as its own process (as `ros2 run` does), subscribes to /joint_states,
commands a step on /joint_commands, records the response, stops the process with SIGINT and
checks from its log that the simulated motor ended disabled.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.utilities import try_shutdown
from sensor_msgs.msg import JointState

from transparency_ros.rosenv import local_ros_env


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
    env = local_ros_env()
    os.environ.update({k: env[k] for k in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE")})
    exe = Path(sys.executable).parent / "actuator_driver"
    proc = subprocess.Popen(
        [
            str(exe),
            "--ros-args",
            "-p",
            f"protocol:={protocol}",
            "-p",
            f"sim_actuator:={actuator}",
            "-p",
            "command_timeout_s:=60.0",
        ],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    context = Context()
    rclpy.init(context=context)
    node = Node("transparency_demo", context=context)
    samples: list[tuple[float, float, float, float]] = []

    def on_state(msg: JointState) -> None:
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        samples.append((stamp, msg.position[0], msg.velocity[0], msg.effort[0]))

    node.create_subscription(JointState, "/joint_states", on_state, 1000)
    commands = node.create_publisher(JointState, "/joint_commands", 10)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    try:
        deadline = time.monotonic() + 20.0
        while len(samples) < 200 and time.monotonic() < deadline:
            time.sleep(0.02)
        if not samples:
            raise RuntimeError("actuator_driver published no /joint_states within 20 s")
        start = len(samples)
        commands.publish(JointState(name=["joint"], position=[target_rad]))
        time.sleep(seconds)
        window = samples[start:]
        rate = (len(window) - 1) / (window[-1][0] - window[0][0]) if len(window) > 1 else 0.0
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            log, _ = proc.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            log, _ = proc.communicate()
        executor.shutdown()
        spinner.join(timeout=5.0)
        node.destroy_node()
        try_shutdown(context=context)
    t0 = samples[start][0]
    trace = [(t - t0, p, v, e) for t, p, v, e in samples[start - 100 :]]
    disabled = "motor enabled at exit: False" in log
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
