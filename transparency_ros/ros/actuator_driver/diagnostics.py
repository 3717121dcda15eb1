"""What ``actuator_driver`` reports on /diagnostics: level and message (fault, not configured,
command timeout, late replies, ok) and the counters of the core, the bus client and the loop."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue

from transparency_ros.canbus.client import ActuatorClient
from transparency_ros.canbus.loop import ControlLoop, PeriodicLoop
from transparency_ros.canbus.multi import MultiControlLoop
from transparency_ros.core.driver import DriverCore, DriverMode
from transparency_ros.core.gc_pauses import GcPauses
from transparency_ros.ros.actuator_driver.hardware import MotorSpec
from transparency_ros.ros.actuator_driver.parameters import NODE_NAME

LATE_WARN_FRACTION = 0.5  # more of a period's replies late than this: WARN


def late_message(late: int, replies: int, timeout_s: float) -> str | None:
    """A warning when most replies of a diagnostics period came after the loop's wait.

    Late replies keep the reply watchdog content (the motor is alive), so a device that is
    persistently slower than ``reply_timeout_s`` runs on without a fault; this says so."""
    if replies <= 0 or late <= LATE_WARN_FRACTION * replies:
        return None
    return (
        f"{late} of {replies} {'reply' if replies == 1 else 'replies'} late this period: the "
        "device or bus answers slower than "
        f"reply_timeout_s {timeout_s * 1e3:g} ms (samples are published at their bus time)"
    )


def driver_status(
    values: dict[str, Any],
    core: DriverCore,
    client: ActuatorClient | None,
    loop: ControlLoop | None,
    late_in_period: Callable[[], str | None],
) -> DiagnosticStatus:
    """The node's status; ``late_in_period`` is asked only when nothing worse is to report."""
    status = DiagnosticStatus(
        name=f"{NODE_NAME}: {values['joint_name']}",
        hardware_id=f"{values['protocol']}:{values['motor_id']}",
    )
    s = core.status
    status.level, status.message = _level(core, client is not None, late_in_period)
    report = _core_report(core, values["interface"], values["channel"])
    if client is not None:
        c = client.counters
        report.update(
            tx=c.tx,
            rx=c.rx,
            tx_errors=c.tx_errors,
            rx_errors=c.rx_errors,
            timeouts=s.missed_replies_total,
            late_replies=c.late,
            duplicate_replies=c.duplicates,
            superseded_replies=loop.superseded_replies if loop is not None else 0,
            malformed=c.malformed,
            other_frames=c.other,
            last_bus_error=c.last_error,
        )
    if loop is not None:
        report.update(_loop_report(loop))
    status.values = [KeyValue(key=k, value=str(val)) for k, val in report.items()]
    return status


def _level(core: DriverCore, configured: bool, late: Callable[[], str | None]) -> tuple[bytes, str]:
    s = core.status
    if s.mode is DriverMode.FAULT:
        return DiagnosticStatus.ERROR, f"FAULT: {s.fault_reason}"
    if not configured:
        return DiagnosticStatus.WARN, "not configured"
    if (message := late()) is not None:
        return DiagnosticStatus.WARN, message
    if s.command_timed_out:  # holding (or damping) after the last command is normal operation
        timeout = core.settings
        return (
            DiagnosticStatus.OK,
            f"{s.mode.value}: {timeout.timeout_action.value} (no command for "
            f"{timeout.command_timeout_s:g} s)",
        )
    return DiagnosticStatus.OK, s.mode.value


def _core_report(core: DriverCore, interface: str, channel: str) -> dict[str, Any]:
    s = core.status
    return {
        "mode": s.mode.value, "interface": interface, "channel": channel,
        "commands_accepted": s.commands_accepted, "commands_rejected": s.commands_rejected,
        "commands_clamped": s.commands_clamped, "missed_replies_total": s.missed_replies_total,
        "missed_replies_in_row": s.missed_replies_in_row, "last_rejection": s.last_rejection,
        "longest_silence_ms": f"{s.longest_silence_s * 1e3:.1f}",
        "fault_reason": s.fault_reason,
    }  # fmt: skip


def _loop_report(loop: PeriodicLoop) -> dict[str, Any]:
    st = loop.stats()
    return {
        "loop_rate_hz": f"{st.rate_hz:.1f}",
        "loop_cycles": st.cycles,
        "overruns": st.overruns,
        "jitter_p50_us": f"{st.jitter_p50_s * 1e6:.0f}",
        "jitter_p99_us": f"{st.jitter_p99_s * 1e6:.0f}",
        "jitter_max_us": f"{st.jitter_max_s * 1e6:.0f}",
        "cycle_cpu_p50_us": f"{st.cpu_p50_s * 1e6:.0f}",
        "cycle_cpu_p99_us": f"{st.cpu_p99_s * 1e6:.0f}",
        # how late cycles started (this computer's stalls), since start
        "cycle_late_p99_us": f"{loop.lateness.percentile(99) * 1e6:.0f}",
        "cycle_late_max_ms": f"{loop.lateness.max_s * 1e3:.1f}",
        # commands that left over half a period after their time, sent again fresh
        "commands_resent": loop.resent_commands,
    }


def robot_statuses(
    values: dict[str, Any], loop: MultiControlLoop, specs: list[MotorSpec]
) -> list[DiagnosticStatus]:
    """Several motors: one status per motor (its core, replies, late ones) and one for the loop
    and its buses."""
    statuses = []
    for motor, spec in zip(loop.motors, specs, strict=True):
        status = DiagnosticStatus(
            name=f"{NODE_NAME}: {motor.name}",
            hardware_id=f"{values['protocol']}:{spec.motor_id}@{spec.channel}",
        )
        status.level, status.message = _level(motor.core, True, lambda: None)
        report = _core_report(motor.core, values["interface"], spec.channel)
        report.update(samples=motor.samples, late_replies=motor.late, duplicates=motor.duplicates,
                      superseded_replies=motor.superseded)  # fmt: skip
        status.values = [KeyValue(key=k, value=str(v)) for k, v in report.items()]
        statuses.append(status)
    worst = max((s.level for s in statuses), key=ord)
    loop_status = DiagnosticStatus(
        name=f"{NODE_NAME}: loop", hardware_id=values["interface"], level=worst
    )
    faulted = [s.name.split(": ", 1)[1] for s in statuses if s.level == DiagnosticStatus.ERROR]
    loop_status.message = f"FAULT: {', '.join(faulted)}" if faulted else (
        f"{len(loop.motors)} motors on {len(loop.clients)} bus(es)")  # fmt: skip
    summary: dict[str, Any] = {"motors": len(loop.motors), "fault_policy": loop.fault_policy}
    summary.update(_loop_report(loop))
    for spec_channel, client in zip(
        dict.fromkeys(s.channel for s in specs), loop.clients, strict=True
    ):
        c = client.counters
        summary[f"{spec_channel}.tx"] = c.tx
        summary[f"{spec_channel}.rx"] = c.rx
        summary[f"{spec_channel}.errors"] = c.tx_errors + c.rx_errors
        summary[f"{spec_channel}.malformed"] = c.malformed
        summary[f"{spec_channel}.other_frames"] = c.other
    loop_status.values = [KeyValue(key=k, value=str(v)) for k, v in summary.items()]
    return [*statuses, loop_status]


def gc_values(pauses: GcPauses) -> list[KeyValue]:
    """The collector's pauses since start-up (``core.gc_pauses``), for the loop's status."""
    return [
        KeyValue(key="gc_collections", value=str(pauses.durations.count)),
        KeyValue(key="gc_full_collections", value=str(pauses.full)),
        KeyValue(key="gc_pause_max_ms", value=f"{pauses.durations.max_s * 1e3:.2f}"),
    ]
