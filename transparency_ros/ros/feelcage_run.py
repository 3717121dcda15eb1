"""Table 2 through the real nodes: ``actuator_driver`` (simulated actuator striking the ball on
the rail), ``contact_estimator`` and ``feel_cage_behavior``, each its own process as ``ros2 run``
starts them, all on loopback in a domain of their own. This process only watches and steers
through ROS interfaces (topics, services, the parameter service), as an experimenter would.

One cell:
1. the behavior sweeps at 1 rev/s with no ball on the rail and the estimator's threshold out of
   reach; from ``settle_s`` on, e_s is the largest |theta_d - theta_a| on /estimated_effort over
   a revolution (the paper's largest steady-state error), measured revolution by revolution
   until it grows by less than epsilon / 4 (the geared U10GB takes about 8 s);
2. the estimator gets contact_onset = e_s + epsilon and contact_release = e_s + epsilon / 2
   (set_parameters_atomically) and is reset; the ball is placed on the rail as soon as the arm is
   clear of it (``/actuator_driver/sim/place_ball``) and the behavior is armed;
3. the trial ends when the behavior reports caged or lost, or when the ball left the workspace
   while the behavior still sweeps (no detection). Ground truth (first arm-ball contact, the
   ball passing the exit) comes from the simulator on ``/actuator_driver/sim/ball``. A cage that
   closes after the ball left counts as lost, as in the core engine.
"""

from __future__ import annotations

import itertools
import math
import subprocess
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, replace

from diagnostic_msgs.msg import DiagnosticStatus
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterType, ParameterValue
from rcl_interfaces.srv import SetParametersAtomically
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from std_srvs.srv import SetBool, Trigger

from transparency_ros.core import feel_cage as fc
from transparency_ros.core.cdr import JointStateFields, decode_joint_state
from transparency_ros.core.config import get_actuator
from transparency_ros.core.errors import TransparencyError
from transparency_ros.core.feel_cage_config import FeelCageSetup
from transparency_ros.ros.harness import (
    Listener,
    driver_left_motor_enabled,
    first_exited,
    start_node,
    stop_node,
)
from transparency_ros.ros.services import ServiceCaller, wait_until
from transparency_ros.rosenv import pick_domain_id, release_domain_id

MAX_SETTLE_REVOLUTIONS = 20
# e_s is a maximum over a smooth revolution: a few hundred samples find it; fewer means the
# stream is broken, not just thinned by a busy machine
MIN_SAMPLES_PER_REVOLUTION = 200
LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)


class FeelCageRunError(TransparencyError, RuntimeError):
    """A real-node trial that could not be run (a node did not come up or answer)."""


@dataclass(frozen=True)
class CellRun:
    record: fc.TrialRecord
    steady_error_rad: float
    error_noise_rad: float  # std of the error over the measured revolution
    sample_rate_hz: float  # /estimated_effort samples received per second while measuring
    # from the stamp of the sample that crossed the threshold to the first sample the motor was
    # driven by the act torque (/joint_setpoints without a held position): t_process plus the
    # command's trip behavior -> driver -> device; None if the behavior never acted
    t_torque_s: float | None = None
    # the longest the driver went without a sample from the ball's first contact to the sample
    # that crossed the threshold (consecutive /joint_setpoints stamps around them): a loaded
    # machine's stalled loop samples the dented arm that much late, and t_feel grows with it.
    # For a detection before the contact (a false one), over the 0.1 s up to it
    sample_gap_s: float | None = None
    # the nodes' warnings and errors during the cell ("node: line"), for whoever reads a
    # surprising record: a stalled loop, a device fault, a refused parameter
    node_warnings: tuple[str, ...] = ()


def _double(name: str, value: float) -> ParameterMsg:
    return ParameterMsg(
        name=name, value=ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=value)
    )


def _values(status: DiagnosticStatus) -> dict[str, str]:
    return {kv.key: kv.value for kv in status.values}


def _optional(text: str) -> float | None:
    return float(text) if text else None


def node_parameters(actuator: str, ball: str, setup: FeelCageSetup) -> dict[str, dict[str, object]]:
    """The three nodes' parameters for one cell (config/feel_cage_nodes.yaml is U10DD's with the
    rubber ball, generated from this): the simulated actuator striking a ball it places on
    request, an estimator whose threshold is out of reach until e_s is known, the behavior."""
    peak = get_actuator(actuator).peak_torque_nm
    return {
        "actuator_driver": {
            "protocol": "moteus",
            "sim_actuator": actuator, "sim_environment": "ball_on_rail", "sim_ball": ball,
            "sim_place_ball": False, "sim_friction_ripple": setup.friction_ripple,
            "k_s": setup.k_s_nm_per_rad, "k_d": 0.0, "publish_rate_hz": setup.sample_rate_hz,
            "position_min_rad": -1000.0, "position_max_rad": 1000.0,
            "velocity_limit_rad_s": 1000.0, "torque_limit_nm": peak, "command_timeout_s": 1.0,
            # the simulated controller's own watchdog at 1 s: four Python processes at 1 kHz on
            # two cores can stall the driver's for over the default 0.1 s, which latches a
            # moteus (and now faults the driver, as it should on a real one); the cell is about
            # contact timing, and a host that died would still stop it within 1 s
            "moteus.watchdog_timeout_s": 1.0,
        },
        "contact_estimator": {
            "k_s": setup.k_s_nm_per_rad, "contact_onset_rad": 9.9, "contact_release_rad": 9.8,
        },
        "feel_cage_behavior": {"actuator": actuator},
    }  # fmt: skip


def run_cell(
    actuator: str, ball: str, setup: FeelCageSetup, *, settle_s: float | None = None,
    params_file: str | None = None,
) -> CellRun:  # fmt: skip
    """Run one Table 2 cell through the three node processes; see the module docstring.
    ``params_file``: the nodes take their parameters from it (--params-file) instead, as a user
    starts them by hand with config/feel_cage_nodes.yaml."""
    settle = setup.settle_s if settle_s is None else settle_s
    params = node_parameters(actuator, ball, setup)
    procs: dict[str, subprocess.Popen[str]] = {}
    logs: dict[str, str] = {}
    domain = pick_domain_id()
    try:
        try:
            for name, values in params.items():
                if params_file:
                    extra = ["--params-file", params_file]
                    procs[name] = start_node(name, {}, extra=extra, domain_id=domain)
                else:
                    procs[name] = start_node(name, values, domain_id=domain)
            listener = Listener("feelcage_runner")

            def died() -> str | None:
                return first_exited(procs) or listener.failure()

            with listener as node:
                run = _trial(node, setup, settle, died)
        finally:
            for name, proc in procs.items():
                logs[name] = stop_node(proc)
            release_domain_id(domain)
            tail = driver_left_motor_enabled(logs.get("actuator_driver", ""))
            if tail:
                raise FeelCageRunError(f"actuator_driver did not report a disabled motor:\n{tail}")
    except FeelCageRunError as error:  # with what the nodes said about it
        raise FeelCageRunError(_with_warnings(str(error), logs)) from error
    return replace(run, node_warnings=node_warnings(logs))


# the levels rclpy's console output names, and Python's own
_NOTABLE = ("[WARN]", "[ERROR]", "[FATAL]", "Traceback", "Error:")
MAX_WARNINGS = 20


def node_warnings(logs: dict[str, str]) -> tuple[str, ...]:
    """The nodes' warning and error lines, "node: line", the first MAX_WARNINGS of them (and a
    count of the rest)."""
    lines = [
        f"{name}: {line.strip()}"
        for name, log in logs.items()
        for line in log.splitlines()
        if any(mark in line for mark in _NOTABLE)
    ]
    if len(lines) > MAX_WARNINGS:
        lines = [*lines[:MAX_WARNINGS], f"... and {len(lines) - MAX_WARNINGS} more"]
    return tuple(lines)


def _with_warnings(message: str, logs: dict[str, str]) -> str:
    notes = node_warnings(logs)
    return message + ("\nthe nodes warned:\n  " + "\n  ".join(notes) if notes else "")


def _trial(node: Node, setup: FeelCageSetup, settle_s: float, died: Callable[[], str | None]
           ) -> CellRun:  # fmt: skip
    errors: deque[float] = deque(maxlen=round(setup.sample_rate_hz))  # one revolution
    trial: list[DiagnosticStatus] = []
    truth: list[DiagnosticStatus] = []
    phase: list[str] = []
    node.create_subscription(DiagnosticStatus, "/feel_cage/trial", trial.append, LATCHED)
    node.create_subscription(DiagnosticStatus, "/actuator_driver/sim/ball", truth.append, LATCHED)

    def on_phase(msg: String) -> None:
        phase.append(msg.data)

    def on_estimate(msg: JointState) -> None:
        errors.extend(msg.position)

    node.create_subscription(String, "/feel_cage/phase", on_phase, LATCHED)

    call = ServiceCaller(node, died)

    check = call.check

    # 1. steady sweep without a ball; e_s over the last revolution
    started = False
    deadline = time.monotonic() + 20.0
    while not started and time.monotonic() < deadline:
        check()
        started = call(Trigger, "/feel_cage_behavior/start", Trigger.Request()).success
        if not started:
            time.sleep(0.1)  # no /joint_states yet
    if not started:
        raise FeelCageRunError("feel_cage_behavior did not start (no /joint_states?)")
    time.sleep(max(0.0, settle_s - 1.0))
    # listen to the 1 kHz error stream only while measuring (CPU for the nodes): revolution by
    # revolution until the largest error grows by less than epsilon / 4 per revolution (geared
    # actuators settle slowly, and the trial starts up to two revolutions later)
    sub = node.create_subscription(JointState, "/estimated_effort", on_estimate, 1000)
    eps = setup.epsilon_rad
    previous = -math.inf
    rates: list[int] = []
    thin: list[int] = []
    for _ in range(MAX_SETTLE_REVOLUTIONS):
        errors.clear()
        time.sleep(1.0)
        check()
        window = list(errors)
        if len(window) < MIN_SAMPLES_PER_REVOLUTION:
            thin.append(len(window))  # a busy moment: measure the next revolution instead
            continue
        rates.append(len(window))
        e_s = max(abs(e) for e in window)
        if e_s - previous < eps / 4:
            break
        previous = e_s
    else:
        raise FeelCageRunError(
            f"the sweep error did not settle within {MAX_SETTLE_REVOLUTIONS} revolutions"
            + (f" ({len(thin)} had too few samples: {thin})" if thin else "")
        )
    node.destroy_subscription(sub)
    mean = sum(window) / len(window)
    noise = math.sqrt(sum((e - mean) ** 2 for e in window) / len(window))

    # 2. threshold, reset, ball, arm
    request = SetParametersAtomically.Request(
        parameters=[
            _double("contact_onset_rad", e_s + eps),
            _double("contact_release_rad", e_s + eps / 2),
        ]
    )
    result = call(SetParametersAtomically, "/contact_estimator/set_parameters_atomically",
                   request).result  # fmt: skip
    if not result.successful:
        raise FeelCageRunError(f"contact_estimator refused the threshold: {result.reason}")
    call(Trigger, "/contact_estimator/reset", Trigger.Request())
    placed = wait_until(
        lambda: call(Trigger, "/actuator_driver/sim/place_ball", Trigger.Request()).success,
        3.0,
        poll_s=0.002,
    )
    if not placed:
        raise FeelCageRunError("the arm never cleared the rail to place the ball")
    # when the act torque reached the motor: raw bytes here, decoded after the trial
    setpoints: list[bytes] = []
    node.create_subscription(JointState, "/joint_setpoints", setpoints.append, 1000, raw=True)
    call(SetBool, "/feel_cage_behavior/arm", SetBool.Request(data=True))

    # 3. until caged/lost, or the ball left while the behavior still sweeps
    def latest_truth() -> dict[str, str]:
        return _values(truth[-1]) if truth else {}

    def finished() -> bool:
        check()
        if trial:
            return True
        exited = latest_truth().get("exit_stamp_s", "")
        return bool(exited) and bool(phase) and phase[-1] == fc.Phase.SWEEP.value

    if not wait_until(finished, 10.0):
        raise FeelCageRunError("the trial did not end within 10 s of arming")
    # let the ball roll on after a cage to learn when it would have left (t_budget)
    time.sleep(setup.after_cage_s if trial else 0.2)
    known = latest_truth()
    contact_s = _optional(known.get("first_contact_stamp_s", ""))
    exit_s = _optional(known.get("exit_stamp_s", ""))
    state = _behavior_state(trial[-1] if trial else None)
    if state.phase is fc.Phase.CAGED and exit_s is not None and (state.done_s or 0.0) > exit_s:
        state = fc.BehaviorState(
            fc.Phase.LOST, 0.0, 0.0, state.detected_s, state.act_start_s, state.done_s
        )
    decoded = [decode_joint_state(data) for data in setpoints]  # (once, for both below)
    detected_s = state.detected_s
    torque_s = _first_unheld_stamp(decoded, detected_s)
    t_torque = None if torque_s is None or detected_s is None else torque_s - detected_s
    gap = (
        None
        if contact_s is None or detected_s is None
        # (a detection before the contact, a false one: the samples' steps up to it)
        else _largest_gap(decoded, min(contact_s, detected_s - 0.1), max(contact_s, detected_s))
    )
    return CellRun(fc.record(state, contact_s, exit_s), e_s, noise, min(rates), t_torque, gap)


def _largest_gap(setpoints: list[JointStateFields], from_s: float, to_s: float) -> float | None:
    """The largest step between consecutive /joint_setpoints stamps that spans any of
    [``from_s``, ``to_s``] (None: no step spans it)."""
    stamps = sorted(fields.stamp_s for fields in setpoints)
    steps = [b - a for a, b in itertools.pairwise(stamps) if b > from_s and a < to_s]
    return max(steps, default=None)


def _first_unheld_stamp(setpoints: list[JointStateFields], after_s: float | None
                        ) -> float | None:  # fmt: skip
    """The stamp of the first /joint_setpoints sample from ``after_s`` on whose motor was not
    held at a position and driven by a torque (the act command: position NaN and a feed-forward
    torque, messages.setpoint_of; a command timeout's damping has no feed-forward)."""
    if after_s is None:
        return None
    for fields in setpoints:
        stamp_s = fields.stamp_s
        unheld = fields.position and math.isnan(fields.position[0]) and fields.effort[0] != 0.0
        if stamp_s >= after_s and unheld:
            return stamp_s
    return None


def _behavior_state(status: DiagnosticStatus | None) -> fc.BehaviorState:
    """The behavior's final state from its /feel_cage/trial report (None: never detected)."""
    if status is None:
        return fc.BehaviorState(fc.Phase.SWEEP)
    v = _values(status)
    return fc.BehaviorState(
        fc.Phase(status.message),
        0.0,
        0.0,
        _optional(v.get("detected_stamp_s", "")),
        _optional(v.get("act_start_s", "")),
        _optional(v.get("done_s", "")),
    )
