"""bag_replay: offset, topic filter, /clock and loop, on a reference bag."""

from __future__ import annotations

import signal
import subprocess
import sys
from pathlib import Path

import pytest

rclpy = pytest.importorskip("rclpy")
from rclpy.context import Context  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.qos import QoSProfile  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from test.ros.conftest import Spinner, wait_for  # noqa: E402
from transparency_ros.bag.reader import open_bag  # noqa: E402

pytestmark = pytest.mark.ros
BAG = Path(__file__).resolve().parents[2] / "bags" / "U10DD" / "h0050.0mm_t01"
EXE = str(Path(sys.executable).parent / "bag_replay")


def _log_times() -> list[int]:
    with open_bag(BAG) as bag:
        return [log for _, log, _ in bag.raw(["/joint_states"])]


def test_offset_filter_and_clock(ros_context: Context) -> None:
    logs = _log_times()
    offset_s = 0.2
    expected = [t for t in logs if t >= logs[0] + offset_s * 1e9]
    node = Node("replay_listener", context=ros_context)
    states: list[JointState] = []
    clocks: list[int] = []
    node.create_subscription(JointState, "/joint_states", states.append, QoSProfile(depth=5000))
    node.create_subscription(
        Clock, "/clock", lambda m: clocks.append(m.clock.sec * 10**9 + m.clock.nanosec), 5000
    )
    spinner = Spinner(ros_context, node)
    try:
        done = subprocess.run(
            [EXE, str(BAG), "--topics", "/joint_states", "--start-offset", str(offset_s),
             "--clock", "--rate", "0.5", "--delay", "1.0", "--wait-for-subscribers", "1"],
            capture_output=True, text=True, timeout=60, check=False,
        )  # fmt: skip
        assert done.returncode == 0, done.stderr
        assert f"published {len(expected)} messages" in done.stderr
        assert wait_for(lambda: len(states) == len(expected), 5.0), (len(states), len(expected))
        assert clocks == sorted(clocks)
        assert clocks[0] >= expected[0] - 10**6 and clocks[-1] == expected[-1]
    finally:
        spinner.stop()
        node.destroy_node()


def test_loop_plays_again_until_interrupted(ros_context: Context) -> None:
    per_pass = len(_log_times())
    node = Node("loop_listener", context=ros_context)
    count = [0]
    node.create_subscription(
        JointState, "/joint_states", lambda _m: count.__setitem__(0, count[0] + 1), 5000
    )
    spinner = Spinner(ros_context, node)
    proc = subprocess.Popen(
        [EXE, str(BAG), "--topics", "/joint_states", "--loop", "--rate", "4", "--delay", "1.0"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert wait_for(lambda: count[0] > 2 * per_pass, 20.0), (count[0], per_pass)
    finally:
        proc.send_signal(signal.SIGINT)
        proc.communicate(timeout=10)
        spinner.stop()
        node.destroy_node()
    assert proc.returncode == 0


def test_a_bad_bag_is_a_clear_error() -> None:
    done = subprocess.run([EXE, "/nonexistent/bag"], capture_output=True, text=True, timeout=30,
                          check=False)  # fmt: skip
    assert done.returncode == 2
    assert "bag_replay: error: /nonexistent/bag: no such bag" in done.stderr
    done = subprocess.run([EXE, str(BAG), "--rate", "0"], capture_output=True, text=True,
                          timeout=30, check=False)  # fmt: skip
    assert done.returncode == 2 and "--rate must be > 0" in done.stderr


def test_a_teardown_that_hangs_ends_the_process_with_its_status() -> None:
    """The bound on the teardown (once a replay printed its count and never exited): a process
    held up by a thread that does not end is ended with the replay's status and a warning."""
    script = (
        "import threading, time\n"
        "from transparency_ros.ros import bag_replay\n"
        "bag_replay.TEARDOWN_S = 0.5\n"
        "bag_replay._bound_teardown(3)\n"
        "threading.Thread(target=time.sleep, args=(60,)).start()  # holds the exit up\n"
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=30, check=False)  # fmt: skip
    assert done.returncode == 3
    assert "bag_replay: warning: the ROS teardown did not end" in done.stderr, done.stderr
