"""core.cdr against rclpy's own serializer, both ways, on generated messages (hypothesis)."""

from __future__ import annotations

import math
import struct

import pytest
from geometry_msgs.msg import WrenchStamped
from hypothesis import given, settings
from hypothesis import strategies as st
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState

from transparency_ros.core.cdr import (
    CdrError,
    JointStateReader,
    decode_joint_state,
    encode_joint_state,
    encode_wrench_stamped,
    header_stamp_ns,
    write_header_stamp,
)

text = st.text(
    st.characters(blacklist_categories=("Cs",), blacklist_characters="\x00"), max_size=12
)
floats = st.floats(allow_nan=True, allow_infinity=True)
doubles = st.lists(floats, max_size=5)
stamps = st.tuples(st.integers(-(2**31), 2**31 - 1), st.integers(0, 2**32 - 1))


def _same(a: tuple[float, ...] | list[float], b: tuple[float, ...] | list[float]) -> bool:
    return len(a) == len(b) and all(
        x == y or (math.isnan(x) and math.isnan(y)) for x, y in zip(a, b, strict=True)
    )


@settings(max_examples=300, deadline=None)
@given(stamps, text, st.lists(text, max_size=4), st.tuples(doubles, doubles, doubles))
def test_joint_state_both_ways(stamp, frame, names, arrays) -> None:  # type: ignore[no-untyped-def]
    p, v, e = arrays
    msg = JointState()
    msg.header.stamp.sec, msg.header.stamp.nanosec = stamp
    msg.header.frame_id = frame
    msg.name, msg.position, msg.velocity, msg.effort = names, p, v, e
    # rclpy's bytes -> ours
    got = decode_joint_state(serialize_message(msg))
    assert (got.sec, got.nanosec) == stamp and got.frame_id == frame and got.name == names
    assert _same(got.position, p) and _same(got.velocity, v) and _same(got.effort, e)
    # ours -> rclpy's deserializer
    back = deserialize_message(
        encode_joint_state(*stamp, frame, names, position=p, velocity=v, effort=e), JointState
    )
    assert (back.header.stamp.sec, back.header.stamp.nanosec) == stamp
    assert back.header.frame_id == frame and list(back.name) == names
    assert _same(list(back.position), p) and _same(list(back.velocity), v)
    assert _same(list(back.effort), e)


@settings(max_examples=200, deadline=None)
@given(stamps, text, st.tuples(floats, floats, floats), st.tuples(floats, floats, floats))
def test_wrench_stamped_read_by_rclpy(stamp, frame, force, torque) -> None:  # type: ignore[no-untyped-def]
    back = deserialize_message(encode_wrench_stamped(*stamp, frame, force, torque), WrenchStamped)
    assert (back.header.stamp.sec, back.header.stamp.nanosec) == stamp
    assert back.header.frame_id == frame
    f, t = back.wrench.force, back.wrench.torque
    assert _same([f.x, f.y, f.z], list(force)) and _same([t.x, t.y, t.z], list(torque))


GOOD = encode_joint_state(1, 2, "base", ["j1", "j2"], position=[0.1, 0.2], velocity=[0.0, 0.0])


@pytest.mark.parametrize(
    ("data", "says"),
    [
        (b"", "not little-endian"),
        (b"\x00\x00\x00\x00" + GOOD[4:], "not little-endian"),  # big-endian CDR
        (GOOD[:10], "header.stamp"),
        (GOOD[:14], "header.frame_id"),
        (GOOD[:30], "name"),
        (GOOD[:-8], "velocity"),
        (GOOD[:12] + struct.pack("<I", 0) + GOOD[16:], "length 0"),
        (GOOD[:12] + struct.pack("<I", 10**9) + GOOD[16:], "header.frame_id"),
        (GOOD[:24] + struct.pack("<I", 2**31) + GOOD[28:], "name"),  # a corrupt count
        (GOOD[:20] + b"X" + GOOD[21:], "not NUL-terminated"),
        (GOOD[:16] + b"\xff\xfe\xfd\x00" + GOOD[20:], "not UTF-8"),
    ],
)
def test_malformed_joint_state_is_refused_with_the_place(data: bytes, says: str) -> None:
    with pytest.raises(CdrError, match=says):
        decode_joint_state(data)


@settings(max_examples=500, deadline=None)
@given(st.binary(max_size=80), st.integers(0, 60))
def test_arbitrary_bytes_decode_or_cdr_error(garbage: bytes, cut: int) -> None:
    """Random bytes, and a good message with bytes replaced: a result or CdrError, nothing else."""
    for data in (b"\x00\x01\x00\x00" + garbage, GOOD[:cut] + garbage[: len(GOOD) - cut]):
        try:
            got = decode_joint_state(data)
        except CdrError as err:
            assert str(err)  # noqa: PT017 - the message names the field and offset
        else:
            assert isinstance(got.name, list)


@settings(max_examples=100, deadline=None)
@given(
    st.lists(
        st.tuples(
            stamps,
            st.sampled_from(["", "base"]),
            st.sampled_from([["j"], ["j", "k"], []]),
            st.integers(0, 2),
            st.integers(0, 2),
            floats,
        ),
        min_size=1,
        max_size=12,
    ),
    st.booleans(),
)
def test_stream_reader_equals_full_decoding(messages, through_rclpy) -> None:  # type: ignore[no-untyped-def]
    """Streams that keep or change their layout, from our encoder or rclpy's (whose padding
    bytes are not zeroed): the cached layout must never leak into a different message."""
    reader = JointStateReader()
    for stamp, frame, names, n_velocity, n_effort, value in messages:
        positions = [value + i for i in range(len(names))]
        args = {
            "position": positions,
            "velocity": [value] * n_velocity,
            "effort": [-value] * n_effort,
        }
        if through_rclpy:
            msg = JointState(name=names, **args)
            msg.header.stamp.sec, msg.header.stamp.nanosec = stamp
            msg.header.frame_id = frame
            data = serialize_message(msg)
        else:
            data = encode_joint_state(*stamp, frame, names, **args)
        got, want = reader(data), decode_joint_state(data)
        assert got[:4] == want[:4]
        for a, b in zip(got[4:], want[4:], strict=True):
            assert _same(a, b)


def test_header_stamp_helpers_on_rclpy_bytes() -> None:
    msg = WrenchStamped()
    msg.header.stamp.sec, msg.header.stamp.nanosec = 1_700_000_000, 123_456_789
    data = serialize_message(msg)
    assert header_stamp_ns(data) == 1_700_000_000_123_456_789
    template = bytearray(data)
    write_header_stamp(template, 5, 6)
    assert header_stamp_ns(bytes(template)) == 5_000_000_006
    back = deserialize_message(bytes(template), WrenchStamped)
    assert (back.header.stamp.sec, back.header.stamp.nanosec) == (5, 6)
    fields = decode_joint_state(encode_joint_state(7, 8, "", ["j"], position=[0.0]))
    assert fields.stamp_ns == 7_000_000_008 and fields.stamp_s == 7 + 8e-9
    with pytest.raises(CdrError, match="header"):
        header_stamp_ns(b"\x00\x00\x00\x00" + bytes(8))
