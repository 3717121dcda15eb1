"""The estimator computes tau_hat against the setpoint the driver applied to each sample
(/joint_setpoints, stamped like /joint_states), through the real executables.

Before, driver and estimator each took theta_d from /joint_commands on their own: after a
one-shot command (a publisher that exits 0.3 s later, as `ros2 topic pub --once` does) one of
them could miss it, and the estimator then held a /contact that never released."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

rclpy = pytest.importorskip("rclpy")
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from geometry_msgs.msg import WrenchStamped  # noqa: E402
from rclpy.context import Context  # noqa: E402
from rclpy.node import Node  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from test.ros.conftest import Spinner, wait_for  # noqa: E402

pytestmark = pytest.mark.ros
BIN = Path(sys.executable).parent

# what `ros2 topic pub --once` does: wait for a subscriber, publish once, linger, exit
ONE_SHOT = """
import sys, time, rclpy
from rclpy.node import Node
from sensor_msgs.msg import JointState
rclpy.init()
node = Node("one_shot")
pub = node.create_publisher(JointState, "/joint_commands", 10)
deadline = time.monotonic() + 10.0
while pub.get_subscription_count() < int(sys.argv[3]) and time.monotonic() < deadline:
    time.sleep(0.01)
names = sys.argv[1].split(",")
for _ in range(int(sys.argv[4])):
    pub.publish(JointState(name=names, position=[float(sys.argv[2])] * len(names)))
    time.sleep(0.1)
time.sleep(0.2)
node.destroy_node()
rclpy.shutdown()
"""


def one_shot(names: list[str], position: float, subscribers: int = 1, times: int = 1) -> None:
    """Publish once (or ``times``, 0.1 s apart) after ``subscribers`` have matched; exit 0.3 s
    after the last."""
    subprocess.run(
        [sys.executable, "-c", ONE_SHOT, ",".join(names), str(position), str(subscribers),
         str(times)],
        check=True, timeout=30.0, env=dict(os.environ),
    )  # fmt: skip


def one_shot_until(
    names: list[str],
    position: float,
    heard: Any,
    *,
    subscribers: int = 1,
    times: int = 1,
    tries: int = 5,
) -> int:
    """One-shot commands, a new publisher each time, until ``heard()`` holds within 2 s of one
    (at most ``tries``). On a loaded machine a reader may learn of a short-lived writer only
    after it has published, and its messages are lost (volatile durability, as with `ros2 topic
    pub --once`); a user publishes again, and so does this stimulus. Returns how many it took."""
    for attempt in range(1, tries + 1):
        one_shot(names, position, subscribers, times)
        if wait_for(heard, 2.0):
            return attempt
    raise AssertionError(f"{tries} one-shot commands of {position} to {names}: none was heard")


class Probe:
    def __init__(self, context: Context) -> None:
        self.node = Node("setpoint_probe", context=context)
        self.states: dict[int, JointState] = {}
        self.setpoints: dict[int, JointState] = {}
        self.estimates: list[JointState] = []
        self.contacts: list[WrenchStamped] = []
        self.releases: list[WrenchStamped] = []
        self.diagnostics: list[Any] = []
        sub = self.node.create_subscription
        sub(JointState, "/joint_states", lambda m: self.states.update({key(m): m}), 1000)
        sub(JointState, "/joint_setpoints", lambda m: self.setpoints.update({key(m): m}), 1000)
        sub(JointState, "/estimated_effort", self.estimates.append, 1000)
        sub(WrenchStamped, "/contact", self.contacts.append, 100)
        sub(WrenchStamped, "/contact_release", self.releases.append, 100)
        sub(DiagnosticArray, "/diagnostics", lambda m: self.diagnostics.extend(m.status), 100)

    def last_setpoint(self, joint: str = "joint") -> float:
        """The driver's latest /joint_setpoints position of ``joint`` (NaN before any)."""
        if not self.setpoints:
            return float("nan")
        msg = list(self.setpoints.values())[-1]  # one call: the spinner thread adds to it
        return float(msg.position[list(msg.name).index(joint)])

    def estimator_values(self) -> dict[str, str]:
        mine = [s for s in self.diagnostics if s.name.startswith("contact_estimator")]
        return {kv.key: kv.value for kv in mine[-1].values} if mine else {}

    def estimator_message(self) -> str:
        mine = [s for s in self.diagnostics if s.name.startswith("contact_estimator")]
        return mine[-1].message if mine else ""


def gap_of(probe: Probe) -> float:
    """theta_d_gap_max_rad in the estimator's latest status (NaN: none yet)."""
    return float(probe.estimator_values().get("theta_d_gap_max_rad", "nan"))


def key(msg: Any) -> int:
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


@pytest.fixture
def nodes(ros_context: Context) -> Iterator[Any]:
    procs: list[subprocess.Popen[str]] = []
    probe = Probe(ros_context)
    spinner = Spinner(ros_context, probe.node)

    def start(exe: str, **params: Any) -> subprocess.Popen[str]:
        args = [a for k, v in params.items() for a in ("-p", f"{k}:={v}")]
        proc = subprocess.Popen(
            [str(BIN / exe), "--ros-args", *args], stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT, text=True, env=dict(os.environ),
        )  # fmt: skip
        procs.append(proc)
        return proc

    yield start, probe
    for proc in procs:
        proc.terminate()
    for proc in procs:
        try:
            proc.communicate(timeout=15.0)
        except subprocess.TimeoutExpired:
            proc.kill()
    spinner.stop()
    probe.node.destroy_node()


def settled_error(probe: Probe, joint: str, window: int = 50) -> float:
    """The largest |theta_d - theta_a| the estimator published for ``joint`` lately."""
    errors = [
        abs(m.position[list(m.name).index(joint)]) for m in probe.estimates[-window:]
        if joint in m.name
    ]  # fmt: skip
    return max(errors) if errors else float("inf")


def test_an_estimator_that_missed_the_command_uses_the_drivers_setpoint(nodes: Any) -> None:
    """The estimator starts after a one-shot command: it never heard it. The driver's
    setpoints give it theta_d; before, it kept theta_d = 0 and reported a contact of -0.7 rad
    that never released."""
    start, probe = nodes
    start("actuator_driver", channel="setpoints_late_estimator", publish_rate_hz=500.0)
    assert wait_for(lambda: len(probe.states) > 50, 20.0), "no /joint_states"
    # (heard: the setpoint on its way; under load the driver's 0.5 s command watchdog may hold
    # it short of 0.7, at the velocity limit's pace: 0.68 beside four CPU hogs)
    one_shot_until(["joint"], 0.7, lambda: abs(probe.last_setpoint() - 0.7) < 0.05)
    assert wait_for(lambda: abs(list(probe.states.values())[-1].position[0] - 0.7) < 0.05, 5.0)
    estimator = start("contact_estimator")
    assert wait_for(lambda: len(probe.estimates) > 200, 20.0), "no /estimated_effort"
    time.sleep(0.5)
    assert settled_error(probe, "joint") < 0.05, probe.estimates[-1]
    if probe.contacts:
        estimator.terminate()
        raise AssertionError(f"{probe.contacts}\n{estimator.communicate(timeout=10)[0]}")
    # every sample has a setpoint with the very same stamp
    common = sorted(set(probe.states) & set(probe.setpoints))
    assert len(common) > 0.95 * len(probe.states), (len(common), len(probe.states))
    state, setpoint = probe.states[common[-1]], probe.setpoints[common[-1]]
    assert list(setpoint.name) == list(state.name) == ["joint"]
    assert abs(setpoint.position[0] - 0.7) < 0.05  # held there (after the command timeout too)
    # (a status of the estimator's after the 200 estimates above: it reports once a second,
    # and on a loaded machine the last one may predate them, 23 samples in)
    assert wait_for(lambda: probe.estimator_values().get("theta_d_source") == "/joint_setpoints"
                    and int(probe.estimator_values().get("samples", 0)) > 200,
                    5.0), probe.estimator_values()  # fmt: skip
    values = probe.estimator_values()
    assert int(values["setpoints_matched"]) > 100, values
    # (on a loaded machine some setpoints come after setpoint_wait_s: counted in
    # setpoints_missing, the nearest stands in; the settled error above shows no harm)


def test_one_shot_commands_to_three_motors_are_followed_by_the_estimate(nodes: Any) -> None:
    """The README's three-motor driver with an estimator running all along; each one-shot
    command is a new publisher that publishes once it has matched one subscriber and exits
    0.3 s later, so the driver, the estimator, both or neither may get it (as with
    `ros2 topic pub --once`). Whatever the driver did, every joint's estimate settles to the
    setpoint it applied and every contact releases."""
    start, probe = nodes
    joints = ["hip", "knee", "ankle"]
    start("actuator_driver", channel="setpoints_three", publish_rate_hz=500.0,
          motor_ids="[1,2,3]", joint_names=f"[{','.join(joints)}]")  # fmt: skip
    start("contact_estimator")
    assert wait_for(lambda: len(probe.estimates) > 100 and len(probe.states) > 100, 20.0)
    for target in (0.6, 0.0, -0.6, 0.3):
        one_shot(joints, target)
        time.sleep(1.0)
        for joint in joints:
            # (what the estimator said lately, for a failure seen only under a loaded suite:
            # no estimate of 'hip' among the last 50)
            lately = [(list(m.name), list(m.position)) for m in probe.estimates[-3:]]
            assert settled_error(probe, joint) < 0.05, (target, joint, len(probe.estimates), lately)
        assert len(probe.releases) == len(probe.contacts), (target, len(probe.contacts))
    common = set(probe.states) & set(probe.setpoints)
    assert len(common) > 0.95 * len(probe.states), (len(common), len(probe.states))


def test_a_clamped_command_is_a_visible_disagreement(nodes: Any) -> None:
    """The estimator hears 0.7 rad; the driver clamps it to 0.4: tau_hat follows the driver's
    setpoint, and /diagnostics says by how much the two differ. (The step itself is a contact
    while the arm catches up, as before: it releases.)"""
    start, probe = nodes
    start("actuator_driver", channel="setpoints_clamped", publish_rate_hz=500.0,
          position_max_rad=0.4, command_timeout_s=30.0)  # fmt: skip
    start("contact_estimator")
    assert wait_for(lambda: len(probe.estimates) > 100, 20.0), "no /estimated_effort"
    # both must hear it: a publisher that has matched a reader may still be unknown to it, so
    # a single message can be lost even then; five, and again until the driver has applied it
    # (clamped), then the status after them -- and again while the estimator has not heard
    # any (its status says so within a few seconds when it has; once, under a loaded suite,
    # the driver heard the five and the estimator none, and nobody published again)
    probe.diagnostics.clear()
    for _ in range(4):
        one_shot_until(["joint"], 0.7, lambda: abs(probe.last_setpoint() - 0.4) < 0.05,
                       subscribers=2, times=5)  # fmt: skip
        if wait_for(lambda: "differs from the last /joint_commands"
                    in probe.estimator_message(), 5.0):  # fmt: skip
            break
    assert "differs from the last /joint_commands" in probe.estimator_message(), (
        probe.estimator_message()
    )
    # the gap is the one at the estimator's latest sample: a status taken after it heard 0.7
    # and before the driver's clamped setpoint reached it says 0.7 (CI, loaded); the gap the
    # two keep is the clamp's
    assert wait_for(lambda: gap_of(probe) == pytest.approx(0.3, abs=1e-6), 5.0), (
        probe.estimator_values()
    )
    values = probe.estimator_values()
    assert values["theta_d_gap_joint"] == "joint"
    assert settled_error(probe, "joint") < 0.05
    assert len(probe.releases) == len(probe.contacts) <= 1, probe.contacts
