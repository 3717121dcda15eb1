"""Header stamps <-> seconds."""

from __future__ import annotations

import pytest

pytest.importorskip("rclpy")
from transparency_ros.ros.conversions import s_to_stamp, stamp_to_s


def test_round_trip_and_carry() -> None:
    stamp = s_to_stamp(100.003)
    assert (stamp.sec, stamp.nanosec) == (100, 3_000_000)
    assert stamp_to_s(stamp) == pytest.approx(100.003, abs=1e-9)
    carried = s_to_stamp(5.9999999999)  # rounds up to a whole second
    assert (carried.sec, carried.nanosec) == (6, 0)
