"""moteus register codec, cross-checked against the moteus library (its frame builder and its
reply parser). moteus.Controller objects are only used to build frames: no transport exists."""

from __future__ import annotations

import math

import moteus
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from moteus import multiplex as mp

from transparency_ros.canbus import moteus_fd as m
from transparency_ros.canbus.errors import CanProtocolError, MalformedFrameError

f32 = st.floats(width=32, allow_nan=False, allow_infinity=False, min_value=-1e6, max_value=1e6)
RES = {m.Res.INT8: mp.INT8, m.Res.INT16: mp.INT16, m.Res.INT32: mp.INT32, m.Res.F32: mp.F32}


def controller(resolution: m.Res) -> moteus.Controller:
    c = moteus.Controller(id=1)
    pr = moteus.PositionResolution()
    for name in (
        "position",
        "velocity",
        "feedforward_torque",
        "kp_scale",
        "kd_scale",
        "watchdog_timeout",
    ):
        setattr(pr, name, RES[resolution])
    c.position_resolution = pr
    return c


@settings(max_examples=300, deadline=None)
@given(
    values=st.tuples(f32, f32, f32, st.floats(0, 1), st.floats(0, 1), st.floats(0.001, 10)),
    resolution=st.sampled_from(list(m.Res)),
    query=st.booleans(),
)
def test_position_command_bytes_equal_the_library(
    values: tuple[float, ...], resolution: m.Res, query: bool
) -> None:
    pos, vel, ff, kp, kd, timeout = values
    theirs = controller(resolution).make_position(
        position=pos,
        velocity=vel,
        feedforward_torque=ff,
        kp_scale=kp,
        kd_scale=kd,
        watchdog_timeout=timeout,
        query=query,
    )
    ours = m.position_command(
        position_rev=pos,
        velocity_rev_s=vel,
        feedforward_torque_nm=ff,
        kp_scale=kp,
        kd_scale=kd,
        watchdog_timeout_s=timeout,
        resolution=resolution,
        query=m.DEFAULT_QUERY if query else None,
    )
    assert ours == theirs.data
    assert m.arbitration_id(0, 1, reply=query) == (0x8000 if query else 0) | 1


def test_stop_and_query_bytes_equal_the_library() -> None:
    c = moteus.Controller(id=1)
    assert m.stop_command() == c.make_stop().data
    assert m.stop_command(m.DEFAULT_QUERY) == c.make_stop(query=True).data
    assert m.encode_query(m.DEFAULT_QUERY) == c.make_query().data


reply_values = st.fixed_dictionaries({
    m.Reg.MODE: st.tuples(st.sampled_from([0, 10, 11]), st.just(m.Res.INT8)),
    m.Reg.POSITION: st.tuples(f32, st.sampled_from(list(m.Res))),
    m.Reg.VELOCITY: st.tuples(f32, st.sampled_from(list(m.Res))),
    m.Reg.TORQUE: st.tuples(f32, st.sampled_from(list(m.Res))),
    m.Reg.TEMPERATURE: st.tuples(st.floats(-20, 120), st.sampled_from(list(m.Res))),
    m.Reg.FAULT: st.tuples(st.integers(0, 100), st.just(m.Res.INT8)),
})  # fmt: skip


@settings(max_examples=300, deadline=None)
@given(values=reply_values)
def test_replies_parse_identically_in_the_library(values: dict[int, tuple[float, m.Res]]) -> None:
    frame = m.pad_fd(m.encode_values(m.REPLY, values))
    theirs = moteus.protocol.parse_reply(frame)
    ours = m.parse_values(frame, m.REPLY)
    assert set(ours) == set(theirs) == set(values)
    for register, value in ours.items():
        other = theirs[register]
        assert (math.isnan(value) and math.isnan(other)) or value == other, register


@pytest.mark.parametrize(
    ("resolution", "scale"), [(m.Res.INT8, 0.01), (m.Res.INT16, 1e-4), (m.Res.INT32, 1e-5)]
)
def test_integer_scaling_saturation_and_nan(resolution: m.Res, scale: float) -> None:
    values = {m.Reg.POSITION: (1e9, resolution), m.Reg.VELOCITY: (math.nan, resolution)}
    parsed = m.parse_values(m.encode_values(m.REPLY, values), m.REPLY)
    limit = {m.Res.INT8: 127, m.Res.INT16: 32767, m.Res.INT32: 2147483647}[resolution]
    assert parsed[m.Reg.POSITION] == pytest.approx(limit * scale)
    assert math.isnan(parsed[m.Reg.VELOCITY])


def test_long_register_runs_and_varuints() -> None:
    values = {reg: (0.5, m.Res.F32) for reg in range(0x20, 0x28)}
    frame = m.encode_values(m.WRITE, values)
    assert frame[:3] == bytes([0x0C, 8, 0x20])  # long form: count in its own byte
    assert m.parse_values(frame, m.WRITE) == dict.fromkeys(range(0x20, 0x28), 0.5)
    big = m.encode_query({0x130: m.Res.INT8})
    assert big == bytes([0x11, 0xB0, 0x02])
    assert m.parse_frame(big)[0].register == 0x130


def test_padding_and_errors() -> None:
    assert m.pad_fd(b"\x01" * 9) == b"\x01" * 9 + b"\x50" * 3
    assert m.pad_fd(b"\x01" * 8) == b"\x01" * 8
    with pytest.raises(CanProtocolError, match="exceeds CAN-FD"):
        m.pad_fd(b"\x00" * 65)
    with pytest.raises(MalformedFrameError, match="subframe type 0x60"):
        m.parse_frame(b"\x60")
    with pytest.raises(MalformedFrameError, match="ends inside a value"):
        m.parse_frame(bytes([0x2F, 0x01, 0x00, 0x00]))
    with pytest.raises(MalformedFrameError, match="ends inside a subframe"):
        m.parse_frame(bytes([0x2C]))
    # found by `make fuzz`: a read of 2^35 registers (varuint count) took minutes to list
    with pytest.raises(MalformedFrameError, match="read of 34359738367 registers"):
        m.parse_frame(bytes([0x10, 0xFF, 0xFF, 0xFF, 0xFF, 0x7F, 0x00]))
    assert len(m.parse_frame(bytes([0x10, 64, 0x00]))) == 64  # the largest a reply can answer
    errors = m.parse_frame(bytes([0x31, 0x05, 0x02]))
    assert errors == [m.Subframe(m.READ_ERROR, 5, None, 2)]
    with pytest.raises(CanProtocolError, match=r"destination id must be 0\.\.127"):
        m.arbitration_id(0, 200, reply=True)


def test_a_reply_in_a_latched_mode_names_why_the_controller_stopped() -> None:
    """Modes as the moteus library numbers them: a fault (with its code) and the position
    watchdog's timeout stop the controller driving; every other mode, or none read, does not."""
    fault = {m.Reg.MODE: float(moteus.Mode.FAULT), m.Reg.FAULT: 33.0}
    assert m.mode_fault(fault) == "moteus fault (code 33)"
    assert m.mode_fault({m.Reg.MODE: float(moteus.Mode.FAULT)}) == "moteus fault (code ?)"
    assert "position timeout" in m.mode_fault({m.Reg.MODE: float(moteus.Mode.TIMEOUT)})
    for mode in (moteus.Mode.STOPPED, moteus.Mode.POSITION, moteus.Mode.ZERO_VELOCITY):
        assert m.mode_fault({m.Reg.MODE: float(mode)}) == ""
    assert m.mode_fault({m.Reg.POSITION: 0.1}) == ""
    assert m.mode_fault({m.Reg.MODE: math.nan}) == ""
