"""The actuator driver's logic, without ROS and without a bus.

:class:`DriverCore` decides what to command each cycle and when to give up:

* **commands**: a joint target (theta_d, theta_d', feed-forward) is validated
  (:func:`parse_joint_command`), clamped to the position/velocity/torque limits and turned into
  an impedance command with the current gains k_s, k_d;
* **command watchdog**: when targets stop arriving for ``command_timeout_s`` the driver holds the
  position it had at that moment (``timeout_action = hold``) or only damps (``damp``);
  before the first target it holds the position it was activated at;
* **reply watchdog**: a motor is silent when no reply has come for ``reply_silence_s`` since
  the first request it left unanswered, *and* it left unanswered at least the requests the loop
  passes as ``min_unanswered`` (half of what the loop should have sent in that time). Judged by
  time, a faster loop does not make it stricter; counting requests too, a stall of the host
  (the scheduler, the collector, the interpreter) during which nothing was asked is not
  taken for a silent motor. Then the driver is in FAULT; the caller sends the protocol's
  disable frames (zero torque, motor off).

Time is passed in (seconds, any monotonic origin); nothing here reads a clock.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from enum import Enum

from transparency_ros.core.errors import TransparencyError


class CommandRejectedError(TransparencyError, ValueError):
    """A joint command that cannot be applied; the message says why."""


class SettingsError(TransparencyError, ValueError):
    """Driver settings that are out of range or inconsistent."""


class DriverMode(str, Enum):
    INACTIVE = "inactive"  # motor released
    ACTIVE = "active"  # commanding
    FAULT = "fault"  # replies lost or bus failure: motor released, waits for re-enable


class TimeoutAction(str, Enum):
    HOLD = "hold"
    DAMP = "damp"


@dataclass(frozen=True)
class DriverSettings:
    k_s_nm_per_rad: float = 2.0
    k_d_nms_per_rad: float = 0.0
    command_timeout_s: float = 0.5
    timeout_action: TimeoutAction = TimeoutAction.HOLD
    timeout_damping_nms_per_rad: float = 0.05
    reply_silence_s: float = 0.1
    position_min_rad: float = -12.5
    position_max_rad: float = 12.5
    velocity_limit_rad_s: float = 20.0
    torque_limit_nm: float = 5.0

    def validated(self) -> DriverSettings:
        problems = []
        if not (math.isfinite(self.k_s_nm_per_rad) and self.k_s_nm_per_rad >= 0):
            problems.append(f"k_s must be >= 0, got {self.k_s_nm_per_rad}")
        if not (math.isfinite(self.k_d_nms_per_rad) and self.k_d_nms_per_rad >= 0):
            problems.append(f"k_d must be >= 0, got {self.k_d_nms_per_rad}")
        if not (math.isfinite(self.command_timeout_s) and self.command_timeout_s > 0):
            problems.append(f"command_timeout_s must be > 0, got {self.command_timeout_s}")
        if not self.timeout_damping_nms_per_rad >= 0:
            problems.append("timeout_damping must be >= 0")
        if not (math.isfinite(self.reply_silence_s) and self.reply_silence_s > 0):
            problems.append(f"reply_silence_s must be > 0, got {self.reply_silence_s}")
        if not self.position_min_rad < self.position_max_rad:
            problems.append(
                f"position limits must satisfy min < max, got "
                f"[{self.position_min_rad}, {self.position_max_rad}]"
            )
        if not self.velocity_limit_rad_s > 0:
            problems.append(f"velocity_limit must be > 0, got {self.velocity_limit_rad_s}")
        if not self.torque_limit_nm > 0:
            problems.append(f"torque_limit must be > 0, got {self.torque_limit_nm}")
        if problems:
            raise SettingsError("; ".join(problems))
        return self


@dataclass(frozen=True)
class JointTarget:
    """theta_d, theta_d' and feed-forward; position None means pure torque (k_s = k_d = 0)."""

    position_rad: float | None
    velocity_rad_s: float = 0.0
    effort_nm: float = 0.0


@dataclass(frozen=True)
class ImpedanceCommand:
    """What to send this cycle: tau = kp (p - p_a) + kd (v - v_a) + tau_ff."""

    position_rad: float
    velocity_rad_s: float
    kp_nm_per_rad: float
    kd_nms_per_rad: float
    torque_ff_nm: float

    @staticmethod
    def zero_torque() -> ImpedanceCommand:
        return ImpedanceCommand(0.0, 0.0, 0.0, 0.0, 0.0)


def parse_joint_command(
    joint_name: str,
    names: Sequence[str],
    positions: Sequence[float],
    velocities: Sequence[float],
    efforts: Sequence[float],
) -> JointTarget:
    """Pick our joint out of a sensor_msgs/JointState-shaped command, or say why not.

    Rules: with names, ours must be among them and every non-empty array has one entry per
    name; without names, arrays hold exactly one joint. Empty velocity or effort mean 0. An
    empty position with an effort is a pure torque command (the impedance gains are not used).
    Every value used must be finite.
    """
    count = len(names) if names else 1
    for label, values in (("position", positions), ("velocity", velocities), ("effort", efforts)):
        if values and len(values) != count:
            raise CommandRejectedError(
                f"{label} has {len(values)} entries for {count} joint(s) {list(names)}"
            )
    if not positions and not efforts:
        raise CommandRejectedError("neither position nor effort given")
    index = 0
    if names:
        try:
            index = list(names).index(joint_name)
        except ValueError:
            raise CommandRejectedError(
                f"joint {joint_name!r} not in command names {list(names)}"
            ) from None
    target = JointTarget(
        position_rad=float(positions[index]) if positions else None,
        velocity_rad_s=float(velocities[index]) if velocities else 0.0,
        effort_nm=float(efforts[index]) if efforts else 0.0,
    )
    for label, value in (("position", target.position_rad), ("velocity", target.velocity_rad_s),
                         ("effort", target.effort_nm)):  # fmt: skip
        if value is not None and not math.isfinite(value):
            raise CommandRejectedError(f"{label} of {joint_name!r} is {value}")
    return target


def _clamp(value: float, low: float, high: float) -> tuple[float, bool]:
    clamped = min(max(value, low), high)
    return clamped, clamped != value


@dataclass
class DriverStatus:
    mode: DriverMode = DriverMode.INACTIVE
    fault_reason: str = ""
    commands_accepted: int = 0
    commands_rejected: int = 0
    commands_clamped: int = 0
    missed_replies_in_row: int = 0
    silent_since_s: float | None = None  # when the first request still unanswered was sent
    longest_silence_s: float = 0.0  # the longest silence that ended with a reply
    missed_replies_total: int = 0
    command_timed_out: bool = False
    last_rejection: str = ""


class DriverCore:
    def __init__(self, settings: DriverSettings) -> None:
        self.settings = settings.validated()
        self.status = DriverStatus()
        self._target: JointTarget | None = None
        self._target_time_s = -math.inf
        self._hold_position_rad = 0.0
        self._timeout_hold_rad: float | None = None
        self.last_position_rad: float | None = None

    # ----------------------------------------------------------------- configuration

    def update_settings(self, **changes: object) -> DriverSettings:
        """Apply new settings atomically, or raise SettingsError and keep the old ones."""
        self.settings = replace(self.settings, **changes).validated()  # type: ignore[arg-type]
        return self.settings

    # ----------------------------------------------------------------- lifecycle

    @property
    def mode(self) -> DriverMode:
        return self.status.mode

    def activate(self, position_rad: float | None) -> None:
        """Start commanding, holding ``position_rad`` (the current one) until a target comes."""
        self.status.mode = DriverMode.ACTIVE
        self.status.fault_reason = ""
        self.status.missed_replies_in_row = 0
        self.status.silent_since_s = None
        self.status.command_timed_out = False
        self._target = None
        self._timeout_hold_rad = None
        self._hold_position_rad = position_rad if position_rad is not None else 0.0

    def deactivate(self) -> None:
        if self.status.mode is not DriverMode.FAULT:
            self.status.mode = DriverMode.INACTIVE

    def fault(self, reason: str) -> None:
        self.status.mode = DriverMode.FAULT
        self.status.fault_reason = reason

    def clear_fault(self) -> None:
        if self.status.mode is DriverMode.FAULT:
            self.status.mode = DriverMode.INACTIVE
            self.status.fault_reason = ""

    # ----------------------------------------------------------------- inputs

    def set_target(self, target: JointTarget, now_s: float) -> bool:
        """Accept a validated target (clamped to the limits); True if clamping was needed."""
        s = self.settings
        p: float | None = None
        p_clamped = False
        if target.position_rad is not None:
            p, p_clamped = _clamp(target.position_rad, s.position_min_rad, s.position_max_rad)
        v, v_clamped = _clamp(
            target.velocity_rad_s, -s.velocity_limit_rad_s, s.velocity_limit_rad_s
        )
        e, e_clamped = _clamp(target.effort_nm, -s.torque_limit_nm, s.torque_limit_nm)
        self._target = JointTarget(p, v, e)
        self._target_time_s = now_s
        self._timeout_hold_rad = None
        self.status.command_timed_out = False
        self.status.commands_accepted += 1
        clamped = p_clamped or v_clamped or e_clamped
        if clamped:
            self.status.commands_clamped += 1
        return clamped

    def reject(self, reason: str) -> None:
        self.status.commands_rejected += 1
        self.status.last_rejection = reason

    def on_feedback(self, position_rad: float, now_s: float | None = None) -> None:
        """A reply (``now_s``: when it was taken, to measure the silence it ends)."""
        st = self.status
        if st.silent_since_s is not None and now_s is not None:
            st.longest_silence_s = max(st.longest_silence_s, now_s - st.silent_since_s)
        st.missed_replies_in_row = 0
        st.silent_since_s = None
        self.last_position_rad = position_rad

    def on_missed_reply(self, sent_s: float, min_unanswered: int = 3) -> bool:
        """A request sent at ``sent_s`` got no reply in its cycle; True when this trips the
        fault: silent for ``reply_silence_s`` over at least ``min_unanswered`` requests."""
        st = self.status
        st.missed_replies_total += 1
        st.missed_replies_in_row += 1
        if st.silent_since_s is None:
            st.silent_since_s = sent_s
        silent_s = sent_s - st.silent_since_s
        if (
            st.mode is DriverMode.ACTIVE
            and silent_s >= self.settings.reply_silence_s
            and st.missed_replies_in_row >= max(min_unanswered, 1)
        ):
            self.fault(
                f"no reply for {silent_s * 1e3:.0f} ms ({st.missed_replies_in_row} requests "
                "unanswered)"
            )
            return True
        return False

    # ----------------------------------------------------------------- output

    def command(self, now_s: float) -> ImpedanceCommand | None:
        """This cycle's command, or None when the motor must not be driven."""
        if self.status.mode is not DriverMode.ACTIVE:
            return None
        s = self.settings
        target = self._target
        if target is None:
            return ImpedanceCommand(
                self._hold_position_rad, 0.0, s.k_s_nm_per_rad, s.k_d_nms_per_rad, 0.0
            )
        if now_s - self._target_time_s > s.command_timeout_s:
            self.status.command_timed_out = True
            if s.timeout_action is TimeoutAction.DAMP:
                return ImpedanceCommand(0.0, 0.0, 0.0, s.timeout_damping_nms_per_rad, 0.0)
            if self._timeout_hold_rad is None:
                last = self.last_position_rad
                fallback = target.position_rad if target.position_rad is not None else 0.0
                self._timeout_hold_rad = last if last is not None else fallback
            return ImpedanceCommand(
                self._timeout_hold_rad, 0.0, s.k_s_nm_per_rad, s.k_d_nms_per_rad, 0.0
            )
        if target.position_rad is None:  # pure torque
            return ImpedanceCommand(0.0, 0.0, 0.0, 0.0, target.effort_nm)
        # theta_d moves on with theta_d' between command updates (streamed trajectories)
        ahead = target.position_rad + target.velocity_rad_s * (now_s - self._target_time_s)
        position = min(max(ahead, s.position_min_rad), s.position_max_rad)
        return ImpedanceCommand(
            position,
            target.velocity_rad_s,
            s.k_s_nm_per_rad,
            s.k_d_nms_per_rad,
            target.effort_nm,
        )
