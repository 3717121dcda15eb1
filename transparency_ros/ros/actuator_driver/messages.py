"""What the driver publishes per sample, serialized (``core.cdr``: cheaper than rclpy's message
objects, and handed as bytes to an estimator composed into the process, ``ros.in_process``).

* /joint_states: what the motors reported, stamped when the replies were on the bus;
* /joint_setpoints: the setpoint each motor was driven with when it answered, stamped exactly
  like the /joint_states sample it belongs to: position = theta_d at the sample's instant (the
  cycle's command advanced by its theta_d' to the stamp, ``canbus.loop.command_at``: a moteus
  advances it so in the device; an MIT device holds the sent position, a difference of at most
  theta_d' times the reply latency), velocity = theta_d', effort = feed-forward torque, for the
  same joints in the same order. A motor not held at a
  position by the impedance law (a pure torque command, damping only after a command timeout)
  has position NaN; one not driven at all (disabled, faulted) has NaN throughout. An estimator
  pairs the two by stamp (``core.setpoint_join``) and so computes tau_hat against the very
  setpoint the motor was following, not its own idea of the last command.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from transparency_ros.canbus.protocol import Feedback
from transparency_ros.core import stamps
from transparency_ros.core.cdr import encode_joint_state
from transparency_ros.core.driver import ImpedanceCommand

NAN = math.nan


def setpoint_of(command: ImpedanceCommand | None) -> tuple[float, float, float]:
    """(theta_d, theta_d', feed-forward) of a cycle's command, NaN where there is none."""
    if command is None:
        return NAN, NAN, NAN
    held = command.kp_nm_per_rad > 0.0  # the impedance law holds a position
    return (command.position_rad if held else NAN), command.velocity_rad_s, command.torque_ff_nm


def _encode(stamp_s: float, names: Sequence[str], columns: Sequence[list[float]]) -> bytes:
    sec, nanosec = stamps.split(stamps.from_seconds(stamp_s))
    position, velocity, effort = columns
    return encode_joint_state(
        sec, nanosec, "", list(names), position=position, velocity=velocity, effort=effort
    )


def encode_states(stamp_s: float, names: Sequence[str], feedback: Sequence[Feedback]) -> bytes:
    return _encode(stamp_s, names, (
        [fb.position_rad for fb in feedback],
        [fb.velocity_rad_s for fb in feedback],
        [fb.torque_nm for fb in feedback],
    ))  # fmt: skip


def encode_setpoints(
    stamp_s: float, names: Sequence[str], commands: Sequence[ImpedanceCommand | None]
) -> bytes:
    """The /joint_setpoints message of a sample stamped ``stamp_s`` (the same float the
    /joint_states message was stamped from, so both carry the same stamp to the nanosecond)."""
    values = [setpoint_of(c) for c in commands]
    return _encode(stamp_s, names, ([v[0] for v in values], [v[1] for v in values],
                                    [v[2] for v in values]))  # fmt: skip
