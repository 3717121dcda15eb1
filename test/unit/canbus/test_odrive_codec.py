"""ODrive CANSimple codec, cross-checked against odrive-can's DBC (firmware 0.6.10) via cantools.

Only the DBC file of odrive-can is used: no odrive-can code runs, and no bus is created
(odrive-can's get_can_bus would pick a network interface under CI=true).
"""

from __future__ import annotations

import struct
from pathlib import Path

import cantools
import odrive_can
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from transparency_ros.canbus import odrive
from transparency_ros.canbus.errors import CanProtocolError, MalformedFrameError

DBC_PATH = Path(odrive_can.__file__).parent / "dbc" / "odrive-cansimple-0.6.10.dbc"
DB = cantools.database.load_file(str(DBC_PATH))
f32 = st.floats(width=32, allow_nan=False, allow_infinity=False)
node_ids = st.integers(0, odrive.MAX_NODE_ID)


def message(node_id: int, cmd: odrive.Cmd) -> cantools.database.Message:
    # the DBC lists axis 0 (node 0); other nodes use the same layouts at node_id << 5
    msg = DB.get_message_by_frame_id(int(cmd))
    assert odrive.arbitration_id(node_id, cmd) == (node_id << 5) | msg.frame_id
    return msg


@settings(max_examples=200, deadline=None)
@given(node=node_ids, pos=f32, vel=f32)
def test_encoder_estimates(node: int, pos: float, vel: float) -> None:
    msg = message(node, odrive.Cmd.GET_ENCODER_ESTIMATES)
    ours = odrive.encode_encoder_estimates(odrive.EncoderEstimates(pos, vel))
    assert ours == msg.encode({"Pos_Estimate": pos, "Vel_Estimate": vel})
    decoded = msg.decode(ours)
    assert (decoded["Pos_Estimate"], decoded["Vel_Estimate"]) == (pos, vel)
    assert odrive.decode_encoder_estimates(ours) == (pos, vel)


@settings(max_examples=200, deadline=None)
@given(node=node_ids, torque=f32)
def test_set_input_torque(node: int, torque: float) -> None:
    msg = message(node, odrive.Cmd.SET_INPUT_TORQUE)
    ours = odrive.encode_set_input_torque(torque)
    assert ours[: msg.length] == msg.encode({"Input_Torque": torque})
    assert odrive.decode_set_input_torque(ours) == torque


@settings(max_examples=200, deadline=None)
@given(target=f32, estimate=f32)
def test_get_torques(target: float, estimate: float) -> None:
    msg = message(0, odrive.Cmd.GET_TORQUES)
    ours = odrive.encode_torques(odrive.Torques(target, estimate))
    assert ours == msg.encode({"Torque_Target": target, "Torque_Estimate": estimate})
    assert odrive.decode_torques(ours) == (target, estimate)


@settings(max_examples=200, deadline=None)
@given(pos=f32, vel_ff=st.integers(-32768, 32767), torque_ff=st.integers(-32768, 32767))
def test_set_input_pos(pos: float, vel_ff: int, torque_ff: int) -> None:
    msg = message(0, odrive.Cmd.SET_INPUT_POS)
    cmd = odrive.InputPos(pos, vel_ff * 1e-3, torque_ff * 1e-3)
    ours = odrive.encode_set_input_pos(cmd)
    assert ours == msg.encode(
        {"Input_Pos": pos, "Vel_FF": cmd.velocity_ff_rev_s, "Torque_FF": cmd.torque_ff_nm}
    )
    back = odrive.decode_set_input_pos(ours)
    assert back.position_rev == pos
    assert round(back.velocity_ff_rev_s * 1e3) == vel_ff
    assert round(back.torque_ff_nm * 1e3) == torque_ff


@settings(max_examples=200, deadline=None)
@given(
    error=st.integers(0, 2**32 - 1),
    state=st.integers(0, 255),
    result=st.integers(0, 255),
    done=st.booleans(),
)
def test_heartbeat(error: int, state: int, result: int, done: bool) -> None:
    msg = message(0, odrive.Cmd.HEARTBEAT)
    ours = odrive.encode_heartbeat(odrive.Heartbeat(error, state, result, done))
    theirs = msg.decode(ours, decode_choices=False)
    assert theirs == {
        "Axis_Error": error,
        "Axis_State": state,
        "Procedure_Result": result,
        "Trajectory_Done_Flag": int(done),
    }
    assert odrive.decode_heartbeat(ours) == (error, state, result, done)


@settings(max_examples=100, deadline=None)
@given(
    state=st.integers(0, 2**32 - 1),
    control=st.integers(0, 2**32 - 1),
    inp=st.integers(0, 2**32 - 1),
)
def test_axis_state_and_controller_mode(state: int, control: int, inp: int) -> None:
    ours = odrive.encode_set_axis_state(state)
    assert ours == message(0, odrive.Cmd.SET_AXIS_STATE).encode({"Axis_Requested_State": state})
    assert odrive.decode_set_axis_state(ours) == state
    mode = odrive.encode_set_controller_mode(control, inp)
    assert mode == message(0, odrive.Cmd.SET_CONTROLLER_MODE).encode(
        {"Control_Mode": control, "Input_Mode": inp}
    )
    assert odrive.decode_set_controller_mode(mode) == (control, inp)


def test_ids_and_errors() -> None:
    assert odrive.arbitration_id(3, odrive.Cmd.SET_INPUT_TORQUE) == 0x6E
    assert odrive.split_id(0x6E) == (3, 0x0E)
    with pytest.raises(CanProtocolError, match=r"node id must be 0\.\.63"):
        odrive.arbitration_id(64, odrive.Cmd.HEARTBEAT)
    with pytest.raises(MalformedFrameError, match="11-bit"):
        odrive.split_id(0x800)
    with pytest.raises(MalformedFrameError, match=r"Get_Encoder_Estimates: expected >= 8 bytes"):
        odrive.decode_encoder_estimates(b"\x00" * 7)
    with pytest.raises(CanProtocolError, match="non-finite"):
        odrive.encode_set_input_torque(float("inf"))
    with pytest.raises(CanProtocolError, match="int16 range"):
        odrive.encode_set_input_pos(odrive.InputPos(0.0, 40.0, 0.0))
    assert struct.unpack("<f", odrive.encode_set_input_torque(1.5)[:4])[0] == 1.5
