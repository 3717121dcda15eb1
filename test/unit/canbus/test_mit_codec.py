"""MIT mode codec, cross-checked bit for bit against mini-cheetah-motor-driver-socketcan.

The reference library's own pipeline (clipping, float_to_uint, bitstring packing, reply
decoding) runs with its two socket calls replaced by capture functions: it never opens a
socket or a bus.
"""

from __future__ import annotations

import math
from typing import Any

import pytest
from bitstring import BitArray
from hypothesis import given, settings
from hypothesis import strategies as st
from motor_driver import canmotorlib as ref

from transparency_ros.canbus import mit
from transparency_ros.canbus.errors import CanProtocolError, MalformedFrameError

AK80_6_V1P1 = mit.MitLimits()  # our defaults


def reference_controller(limits: mit.MitLimits, reply: bytes) -> tuple[Any, list[bytes]]:
    """The library's CanMotorController without its socket; returns it and the sent frames."""
    controller = object.__new__(ref.CanMotorController)
    controller.motorParams = {
        "P_MIN": limits.p_min_rad, "P_MAX": limits.p_max_rad,
        "V_MIN": limits.v_min_rad_s, "V_MAX": limits.v_max_rad_s,
        "KP_MIN": limits.kp_min, "KP_MAX": limits.kp_max,
        "KD_MIN": limits.kd_min, "KD_MAX": limits.kd_max,
        "T_MIN": limits.t_min_nm, "T_MAX": limits.t_max_nm,
        "AXIS_DIRECTION": 1,
    }  # fmt: skip
    controller._p_des_BitArray = BitArray(uint=0, length=16)
    controller._v_des_BitArray = BitArray(uint=0, length=12)
    controller._kp_BitArray = BitArray(uint=0, length=12)
    controller._kd_BitArray = BitArray(uint=0, length=12)
    controller._tau_BitArray = BitArray(uint=0, length=12)
    controller._cmd_bytes = BitArray(uint=0, length=64)
    controller._recv_bytes = BitArray(uint=0, length=48)
    sent: list[bytes] = []
    controller._send_can_frame = sent.append
    controller._recv_can_frame = lambda: (0, len(reply), reply)
    return controller, sent


limits_strategy = st.builds(
    lambda p, v, kp, kd, t: mit.MitLimits(-p, p, -v, v, 0.0, kp, 0.0, kd, -t, t),
    st.sampled_from([12.5, 95.5, 12.56]),
    st.sampled_from([22.5, 45.0, 50.0, 76.0]),
    st.sampled_from([500.0]),
    st.sampled_from([5.0]),
    st.sampled_from([12.0, 18.0, 25.0, 54.0]),
)


@settings(max_examples=300, deadline=None)
@given(data=st.data(), limits=limits_strategy)
def test_command_frame_bits_equal_the_reference(data: st.DataObject, limits: mit.MitLimits) -> None:
    def within(low: float, high: float) -> float:
        return data.draw(st.floats(low, high, allow_nan=False))

    cmd = mit.MitCommand(
        within(limits.p_min_rad, limits.p_max_rad),
        within(limits.v_min_rad_s, limits.v_max_rad_s),
        within(limits.kp_min, limits.kp_max),
        within(limits.kd_min, limits.kd_max),
        within(limits.t_min_nm, limits.t_max_nm),
    )
    reply = mit.encode_reply(1, 0.0, 0.0, 0.0, limits)
    controller, sent = reference_controller(limits, reply)
    controller.send_rad_command(cmd.position_rad, cmd.velocity_rad_s, cmd.kp, cmd.kd, cmd.torque_nm)
    assert sent == [mit.encode_command(cmd, limits)]


@settings(max_examples=300, deadline=None)
@given(data=st.data(), limits=limits_strategy)
def test_reply_decodes_the_same_in_the_reference(
    data: st.DataObject, limits: mit.MitLimits
) -> None:
    p = data.draw(st.floats(limits.p_min_rad, limits.p_max_rad))
    v = data.draw(st.floats(limits.v_min_rad_s, limits.v_max_rad_s))
    t = data.draw(st.floats(limits.t_min_nm, limits.t_max_nm))
    frame = mit.encode_reply(1, p, v, t, limits)
    controller, _ = reference_controller(limits, frame)
    theirs = controller.send_rad_command(0.0, 0.0, 0.0, 0.0, 0.0)
    ours = mit.decode_reply(frame, limits)
    assert (ours.position_rad, ours.velocity_rad_s, ours.torque_nm) == theirs
    # and the quantisation error is within one step of each range
    one_ulp_more = 1 + 1e-12  # the error is exactly one step at the top of the range
    assert (
        abs(ours.position_rad - p) <= (limits.p_max_rad - limits.p_min_rad) / 65535 * one_ulp_more
    )
    assert abs(ours.torque_nm - t) <= (limits.t_max_nm - limits.t_min_nm) / 4095 * one_ulp_more


@settings(max_examples=500, deadline=None)
@given(x=st.floats(-12.5, 12.5), bits=st.sampled_from([12, 16]))
def test_float_to_uint_equals_the_reference(x: float, bits: int) -> None:
    ours = mit.float_to_uint(x, -12.5, 12.5, bits)
    assert ours == ref.float_to_uint(x, -12.5, 12.5, bits)
    assert mit.uint_to_float(ours, -12.5, 12.5, bits) == ref.uint_to_float(ours, -12.5, 12.5, bits)
    assert 0 <= ours <= (1 << bits) - 1


@settings(max_examples=300, deadline=None)
@given(
    cmd=st.builds(
        mit.MitCommand,
        st.floats(-12.5, 12.5),
        st.floats(-22.5, 22.5),
        st.floats(0, 500),
        st.floats(0, 5),
        st.floats(-12, 12),
    )
)
def test_command_round_trip_within_one_step(cmd: mit.MitCommand) -> None:
    back = mit.decode_command(mit.encode_command(cmd, AK80_6_V1P1), AK80_6_V1P1)
    steps = (25 / 65535, 45 / 4095, 500 / 4095, 5 / 4095, 24 / 4095)
    for sent, got, step in zip(cmd, back, steps, strict=True):
        assert got <= sent + 1e-9 and sent - got <= step * (1 + 1e-9)  # truncation, like firmware


def test_known_frames() -> None:
    assert mit.ENTER_MOTOR_MODE.hex() == "fffffffffffffffc"
    assert mit.EXIT_MOTOR_MODE.hex() == "fffffffffffffffd"
    assert mit.SET_ZERO.hex() == "fffffffffffffffe"
    zero = mit.encode_command(mit.MitCommand(0, 0, 0, 0, 0), AK80_6_V1P1)
    assert zero.hex() == "7fff7ff0000007ff"  # mid-scale p, v, t; zero gains


def test_clamping_and_bad_values() -> None:
    high = mit.encode_command(mit.MitCommand(99, 99, 999, 99, 99), AK80_6_V1P1)
    assert high.hex() == "ffffffffffffffff"
    with pytest.raises(CanProtocolError, match="non-finite"):
        mit.encode_command(mit.MitCommand(math.nan, 0, 0, 0, 0), AK80_6_V1P1)
    with pytest.raises(CanProtocolError, match="p range must satisfy min < max"):
        mit.MitLimits(p_min_rad=1.0, p_max_rad=-1.0)


def test_ak_variant_and_malformed_replies() -> None:
    frame = mit.encode_reply(7, 1.0, -2.0, 0.5, AK80_6_V1P1, temperature_raw=65, error_code=3)
    assert len(frame) == 8
    reply = mit.decode_reply(frame, AK80_6_V1P1)
    assert (reply.motor_id, reply.temperature_raw, reply.error_code) == (7, 65, 3)
    assert reply.position_rad == pytest.approx(1.0, abs=4e-4)
    short = mit.decode_reply(frame[:6], AK80_6_V1P1)
    assert short.temperature_raw is None and short.position_rad == reply.position_rad
    for bad in (b"", frame[:5], frame + b"\x00", frame[:7]):
        with pytest.raises(MalformedFrameError, match="6 or 8 bytes"):
            mit.decode_reply(bad, AK80_6_V1P1)
    with pytest.raises(MalformedFrameError, match="8 bytes"):
        mit.decode_command(b"\x00" * 7, AK80_6_V1P1)
    with pytest.raises(MalformedFrameError, match="special frame"):
        mit.decode_command(mit.EXIT_MOTOR_MODE, AK80_6_V1P1)
