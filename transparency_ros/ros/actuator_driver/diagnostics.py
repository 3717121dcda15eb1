"""What ``actuator_driver`` reports on /diagnostics: level and message (fault, not configured,
command timeout, late replies, ok) and the counters of the core, the bus client and the loop."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue

from transparency_ros.canbus.client import ActuatorClient
from transparency_ros.canbus.loop import ControlLoop
from transparency_ros.core.driver import DriverCore, DriverMode
from transparency_ros.ros.actuator_driver.parameters import NODE_NAME

LATE_WARN_FRACTION = 0.5  # more of a period's replies late than this: WARN


def late_message(late: int, replies: int, timeout_s: float) -> str | None:
    """A warning when most replies of a diagnostics period came after the loop's wait.

    Late replies keep the reply watchdog content (the motor is alive), so a device that is
    persistently slower than ``reply_timeout_s`` runs on without a fault; this says so."""
    if replies <= 0 or late <= LATE_WARN_FRACTION * replies:
        return None
    return (
        f"{late} of {replies} replies late this period: the device or bus answers slower than "
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
    if s.mode is DriverMode.FAULT:
        status.level, status.message = DiagnosticStatus.ERROR, f"FAULT: {s.fault_reason}"
    elif client is None:
        status.level, status.message = DiagnosticStatus.WARN, "not configured"
    elif s.command_timed_out:
        status.level = DiagnosticStatus.WARN
        status.message = f"no command for {core.settings.command_timeout_s} s: "
        status.message += core.settings.timeout_action.value
    elif (late := late_in_period()) is not None:
        status.level, status.message = DiagnosticStatus.WARN, late
    else:
        status.level, status.message = DiagnosticStatus.OK, s.mode.value
    report: dict[str, Any] = {
        "mode": s.mode.value, "interface": values["interface"],
        "channel": values["channel"], "commands_accepted": s.commands_accepted,
        "commands_rejected": s.commands_rejected, "commands_clamped": s.commands_clamped,
        "missed_replies_total": s.missed_replies_total,
        "missed_replies_in_row": s.missed_replies_in_row, "last_rejection": s.last_rejection,
    }  # fmt: skip
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
            malformed=c.malformed,
            other_frames=c.other,
            last_bus_error=c.last_error,
        )
    if loop is not None:
        st = loop.stats()
        report.update(
            loop_rate_hz=f"{st.rate_hz:.1f}",
            loop_cycles=st.cycles,
            overruns=st.overruns,
            jitter_p50_us=f"{st.jitter_p50_s * 1e6:.0f}",
            jitter_p99_us=f"{st.jitter_p99_s * 1e6:.0f}",
            jitter_max_us=f"{st.jitter_max_s * 1e6:.0f}",
        )
    status.values = [KeyValue(key=k, value=str(val)) for k, val in report.items()]
    return status
