"""Drop trials through the real nodes, each recorded as a rosbag2 bag (MCAP) by the bag contract.

``actuator_driver`` (simulated actuator with ``sim_environment:=drop_rig``) and
``contact_estimator`` run as their own processes on loopback in a domain of their own. This
process commands theta_d = 0, lifts and drops the shuttle through the driver's services and
records /joint_states, /joint_commands, /contact, /estimated_effort as they arrive, plus the
rig's DAQ blocks written out as the contract's 10 kHz /load_cell and /shuttle/height messages.

Per trial: set ``sim_drop_height_m``, lift the shuttle (``~/sim/lift``), let the arm settle,
command theta_d = 0, reset the estimator, wait until it has estimated a sample stamped after
that command (it is matched to the driver's streams and estimating: on a busy machine that can
take a second after its process started, and a drop before it was detected late or not at all),
start recording, command theta_d = 0 again (the trial's), drop (``~/sim/drop``), record until
/joint_states, the DAQ and /estimated_effort carry stamps the free-fall time plus
``after_contact_s`` after the drop (not that much wall-clock time: on a busy machine they arrive
late), stop, write the bag (atomically; a bag directory that cannot take it is refused before
the first trial).
"""

from __future__ import annotations

import contextlib
import math
import subprocess
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from geometry_msgs.msg import WrenchStamped
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import Trigger

from transparency_ros.bag.writer import BagWriter, check_writable, message_types, time_msg
from transparency_ros.core.cdr import CdrError, decode_joint_state, header_stamp_ns
from transparency_ros.core.config import get_actuator, load_drop_test
from transparency_ros.core.drop_rig import GRAVITY
from transparency_ros.core.errors import TransparencyError
from transparency_ros.core.interrupts import deferred_interrupts
from transparency_ros.ros.harness import (
    Listener,
    driver_left_motor_enabled,
    first_exited,
    start_node,
    stop_node,
)
from transparency_ros.ros.recorder import Recorder
from transparency_ros.ros.services import ServiceCaller
from transparency_ros.rosenv import pick_domain_id, release_domain_id

RECORDED = {
    "/joint_states": JointState,
    "/joint_commands": JointState,
    "/contact": WrenchStamped,
    "/estimated_effort": JointState,
}
DAQ_TOPIC = "/actuator_driver/sim/daq"
# how long a trial waits for the estimator to estimate a sample stamped after its command (its
# process starting on a busy machine; the setpoint join holds a joint's first samples up to 5 s)
ESTIMATOR_WAIT_S = 20.0
# how far the rig's streams may lag behind the trial's end before the trial is refused (on a
# loaded 2-core machine /joint_states reached this process 250 ms after their stamps, and a
# trial recorded for its wall-clock time lost its contact)
STREAM_LAG_S = 10.0


class RigRunError(TransparencyError, RuntimeError):
    """A drop trial that could not be run."""


@dataclass(frozen=True)
class TrialBag:
    path: Path
    height_m: float
    messages: int
    interrupted: bool = False  # closed by Ctrl-C / SIGTERM during the trial


def _daq_stamp_ns(sec: float, frac: float) -> int:
    """A DAQ sample's stamp [ns] from its whole seconds and fraction (``sim_rig.DAQ_COLUMNS``)."""
    return round(sec) * 10**9 + round(frac * 1e9)


def _daq_messages(blocks: list[Float64MultiArray]) -> list[tuple[str, int, Any]]:
    """DAQ blocks -> (topic, stamp [ns], rosbags message) for /load_cell and /shuttle/height."""
    types = message_types()
    out: list[tuple[str, int, Any]] = []
    for block in blocks:
        data = block.data
        for i in range(0, len(data) - 3, 4):
            sec, frac, force, height = data[i], data[i + 1], data[i + 2], data[i + 3]
            ns = _daq_stamp_ns(sec, frac)
            stamp = time_msg(ns)
            vec = types["geometry_msgs/msg/Vector3"]
            wrench = types["geometry_msgs/msg/WrenchStamped"](
                header=types["std_msgs/msg/Header"](stamp=stamp, frame_id="load_cell"),
                wrench=types["geometry_msgs/msg/Wrench"](
                    force=vec(x=0.0, y=0.0, z=float(force)), torque=vec(x=0.0, y=0.0, z=0.0)
                ),
            )
            point = types["geometry_msgs/msg/PointStamped"](
                header=types["std_msgs/msg/Header"](stamp=stamp, frame_id="rail"),
                point=types["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=float(height)),
            )
            out.append(("/load_cell", ns, wrench))
            out.append(("/shuttle/height", ns, point))
    return out


def trial_name(height_m: float, trial: int) -> str:
    return f"h{height_m * 1000:06.1f}mm_t{trial:02d}"


def existing_trials(out_dir: Path, actuator: str, heights_m: Sequence[float], trials: int
                    ) -> str | None:  # fmt: skip
    """What is wrong when trial bags of this run are there already (never overwritten), else
    None; checked before any node starts."""
    names = [trial_name(h, t) for h in heights_m for t in range(1, trials + 1)]
    taken = [n for n in names if (out_dir / actuator / n).exists()]
    if not taken:
        return None
    return (
        f"{len(taken)} trial bag(s) of {actuator} exist already ({', '.join(taken[:3])}"
        f"{', ...' if len(taken) > 3 else ''}): choose another --out or remove them"
    )


def run_rig(
    actuator: str,
    heights_m: Sequence[float],
    out_dir: Path,
    *,
    trials_per_height: int = 1,
    after_contact_s: float = 0.3,
    seed: int = 0,
    progress: Callable[[str], None] = lambda _text: None,
    written: Callable[[TrialBag], None] = lambda _bag: None,
) -> list[TrialBag]:
    """Record the trials; ``written`` hears of each bag as soon as it is closed (an interrupted
    trial's bag included, before the interruption propagates)."""
    drop = load_drop_test()
    get_actuator(actuator)  # a clear error for an unknown name
    for h in heights_m:
        low, high = drop.drop_height_range_m
        if not (0.0 < h <= 2.0):
            raise RigRunError(f"drop height {h} m out of range (the paper: {low}-{high} m)")
    named = [trial_name(h, 1) for h in heights_m]
    twice = sorted({n for n in named if named.count(n) > 1})
    if twice:  # each height's bags are named after it: the second would meet the first's
        raise RigRunError(
            f"drop heights given twice ({', '.join(n.split('_')[0] for n in twice)}; bags are "
            f"named to 0.1 mm): give each height once and repeats with --trials"
        )
    bag_dir = out_dir / actuator
    taken = existing_trials(out_dir, actuator, heights_m, trials_per_height)
    if taken:
        raise RigRunError(f"{out_dir}: {taken}")
    check_writable(bag_dir)
    domain = pick_domain_id()
    k_s, threshold = drop.k_s_nm_per_rad, drop.threshold_rad
    procs: dict[str, subprocess.Popen[str]] = {}
    bags: list[TrialBag] = []
    try:
        procs["actuator_driver"] = start_node("actuator_driver", {
            "sim_actuator": actuator, "sim_environment": "drop_rig", "sim_rig_seed": seed,
            "k_s": k_s, "k_d": drop.k_d_nms_per_rad, "position_min_rad": -100.0,
            "position_max_rad": 100.0, "command_timeout_s": 60.0,
            "torque_limit_nm": get_actuator(actuator).peak_torque_nm,
        }, domain_id=domain)  # fmt: skip
        procs["contact_estimator"] = start_node("contact_estimator", {
            "k_s": k_s, "contact_onset_rad": threshold, "contact_release_rad": threshold / 2,
        }, domain_id=domain)  # fmt: skip
        listener = Listener("transparency_rig")
        with listener as node:
            call = ServiceCaller(node, lambda: first_exited(procs) or listener.failure())
            station = _Station(node, call)
            station.position(20.0, "within 20 s of starting")
            mass = drop.shuttle_mass_for(actuator)
            for h in heights_m:
                for trial in range(1, trials_per_height + 1):
                    name = trial_name(h, trial)
                    progress(f"{actuator} {name}")
                    _set_height(call, h)
                    call(Trigger, "/actuator_driver/sim/lift", Trigger.Request())
                    time.sleep(0.5)  # the arm springs back, and stops where friction holds it
                    # zero the virtual spring where the arm rests (geared actuators stop up to
                    # tau_s / k_s from theta_d, more than the 0.1 rad threshold), then listen
                    rest = station.position(5.0, "while the arm rests")
                    commanded_ns = station.command(rest)
                    time.sleep(0.1)
                    call(Trigger, "/contact_estimator/reset", Trigger.Request())
                    # the estimator in the loop before the trial, not catching up during the
                    # impact (nor its start-up inside the bag)
                    station.wait_estimating(commanded_ns)
                    custom = {
                        "transparency.actuator": actuator,
                        "transparency.k_s": repr(k_s),
                        "transparency.k_d": repr(drop.k_d_nms_per_rad),
                        "transparency.threshold_rad": repr(threshold),
                        "transparency.shuttle_mass_kg": repr(mass),
                        "transparency.arm_length_m": repr(drop.arm_length_m),
                        "transparency.arm_inertia_kgm2": repr(drop.arm_inertia_kgm2),
                        "transparency.drop_height_m": repr(h),
                        "transparency.trial": "drop_test",
                    }
                    path = bag_dir / name
                    bag = BagWriter(path, custom)
                    try:
                        with bag:
                            recorded = station.record_drop(bag, rest, h, after_contact_s)
                    except KeyboardInterrupt:  # Ctrl-C or SIGTERM: the bag keeps the trial so far
                        if path.exists():
                            written(TrialBag(path, h, bag.count, interrupted=True))
                        raise
                    if not recorded.get("/joint_states") or not recorded.get("/load_cell"):
                        raise RigRunError(f"trial {name}: no /joint_states or no DAQ recorded")
                    trial_bag = TrialBag(path, h, bag.count)
                    written(trial_bag)
                    bags.append(trial_bag)
    finally:
        logs = {name: stop_node(proc) for name, proc in procs.items()}
        release_domain_id(domain)
        tail = driver_left_motor_enabled(logs.get("actuator_driver", ""))
        if tail:
            raise RigRunError(f"actuator_driver did not report a disabled motor:\n{tail}")
    return bags


class _Station:
    """This process's side of the rig: the theta_d publisher, the recorder and the DAQ."""

    def __init__(self, node: Any, call: ServiceCaller) -> None:
        self.node, self.call = node, call
        self.newest_estimate_ns = -1  # the newest /estimated_effort stamp heard
        self._state: bytes | None = None  # the latest /joint_states sample, serialized
        self._states_heard = 0
        self.newest_state_ns = -1  # the newest /joint_states stamp heard
        self.newest_daq_ns = -1  # the newest DAQ sample's stamp heard while recording
        # the recorder's subscriptions serve these too: none made and destroyed per trial
        self.recorder = Recorder(
            node,
            RECORDED,
            watch={"/estimated_effort": self._on_estimate, "/joint_states": self._on_state},
        )
        self.commands = node.create_publisher(JointState, "/joint_commands", 10)
        self.daq: list[Float64MultiArray] = []
        self.recording = False
        node.create_subscription(Float64MultiArray, DAQ_TOPIC, self._on_daq, 100)

    def _on_estimate(self, data: bytes) -> None:
        try:
            stamp_ns = header_stamp_ns(data)
        except CdrError:
            return  # not ours to judge: the recorder keeps it, eval reads it
        self.newest_estimate_ns = max(self.newest_estimate_ns, stamp_ns)

    def _on_state(self, data: bytes) -> None:
        self._state = data
        self._states_heard += 1
        with contextlib.suppress(CdrError):  # not ours to judge: the recorder keeps it
            self.newest_state_ns = max(self.newest_state_ns, header_stamp_ns(data))

    def position(self, timeout_s: float, what: str) -> float:
        """The arm's position now: the next /joint_states sample (RigRunError naming ``what``)."""
        heard = self._states_heard
        if not self._poll(lambda: self._states_heard != heard, timeout_s):
            raise RigRunError(f"actuator_driver published no /joint_states {what}")
        try:
            return float(decode_joint_state(self._state or b"").position[0])
        except (CdrError, IndexError) as err:
            raise RigRunError(f"/joint_states {what}: no joint position ({err})") from err

    def wait_estimating(self, since_ns: int, timeout_s: float = ESTIMATOR_WAIT_S) -> None:
        """Return once the estimator has estimated a sample stamped at or after ``since_ns``;
        RigRunError after ``timeout_s`` (ServiceCallError when a node process has exited)."""
        if not self._poll(lambda: self.newest_estimate_ns >= since_ns, timeout_s):
            heard = "none" if self.newest_estimate_ns < 0 else "only of older samples"
            raise RigRunError(
                f"contact_estimator estimated no /joint_states sample stamped after the "
                f"trial's command within {timeout_s:g} s (/estimated_effort heard: {heard})"
            )

    def _poll(self, condition: Callable[[], bool], timeout_s: float) -> bool:
        """Whether ``condition`` came true within ``timeout_s``, checking the node processes
        meanwhile (ServiceCallError when one has exited)."""
        deadline = time.monotonic() + timeout_s
        while not condition():
            self.call.check()
            if time.monotonic() > deadline:
                return False
            time.sleep(0.005)
        return True

    def _on_daq(self, msg: Float64MultiArray) -> None:
        if self.recording:
            self.daq.append(msg)
            data = msg.data
            if len(data) >= 4:  # the block's last sample: stamp_sec, stamp_frac_s, ...
                stamp_ns = _daq_stamp_ns(data[len(data) - 4], data[len(data) - 3])
                self.newest_daq_ns = max(self.newest_daq_ns, stamp_ns)

    def _newest(self) -> dict[str, int]:
        """The newest stamp [ns] heard on each stream a trial waits for (-1: none yet)."""
        return {"/joint_states": self.newest_state_ns, "DAQ": self.newest_daq_ns,
                "/estimated_effort": self.newest_estimate_ns}  # fmt: skip

    def command(self, theta_d: float) -> int:
        """Publish theta_d; return the command's stamp [ns]."""
        now = self.node.get_clock().now()
        msg = JointState(name=["joint"], position=[theta_d])
        msg.header.stamp = now.to_msg()
        self.commands.publish(msg)
        return int(now.nanoseconds)

    def record_drop(
        self, bag: BagWriter, theta_d: float, height_m: float, after_contact_s: float
    ) -> dict[str, int]:
        """One drop into ``bag``: the topics as they arrive, the DAQ blocks at the end (or at
        the signal that stops it); returns the number of messages per topic.

        The trial ends when /joint_states, the DAQ and the estimator's /estimated_effort have
        delivered samples stamped the free fall plus ``after_contact_s`` after the drop, not
        after that much wall-clock time: on a busy machine the streams arrive late, and the
        estimator's /contact later still (RigRunError beyond ``STREAM_LAG_S``)."""
        bag.add("/load_cell", "geometry_msgs/msg/WrenchStamped")
        bag.add("/shuttle/height", "geometry_msgs/msg/PointStamped")
        self.daq.clear()
        self.newest_daq_ns = -1
        self.recording = True
        self.recorder.start(bag)
        try:
            self.command(theta_d)  # recorded: theta_d of this trial
            time.sleep(0.05)
            self.call(Trigger, "/actuator_driver/sim/drop", Trigger.Request())
            # the rig let go before its answer came: stamps up to here cover the fall at least
            trial_s = math.sqrt(2.0 * height_m / GRAVITY) + after_contact_s
            end_ns = int(self.node.get_clock().now().nanoseconds) + round(trial_s * 1e9)
            time.sleep(trial_s)
            if not self._poll(lambda: min(self._newest().values()) >= end_ns, STREAM_LAG_S):
                behind = ", ".join(
                    f"{k} {'none' if v < 0 else f'{(end_ns - v) * 1e-9:.2f} s short'}"
                    for k, v in self._newest().items()
                )
                raise RigRunError(
                    f"the rig's streams did not reach the trial's end within {STREAM_LAG_S:g} s "
                    f"of it ({behind}): the machine is too busy to record this trial"
                )
        finally:
            # also when interrupted: what arrived up to the signal goes into the bag
            with deferred_interrupts():
                self.recording = False
                counts = self.recorder.stop()
                for topic, ns, msg in _daq_messages(self.daq):
                    bag.write_message(topic, ns, msg)
                    counts[topic] = counts.get(topic, 0) + 1
        return counts


def _set_height(call: ServiceCaller, height_m: float) -> None:
    value = ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=height_m)
    request = SetParameters.Request(
        parameters=[ParameterMsg(name="sim_drop_height_m", value=value)]
    )
    result = call(SetParameters, "/actuator_driver/set_parameters", request)
    if not result.results or not result.results[0].successful:
        reason = result.results[0].reason if result.results else "no result"
        raise RigRunError(f"actuator_driver refused sim_drop_height_m={height_m}: {reason}")
