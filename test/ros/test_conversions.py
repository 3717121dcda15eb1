"""Header stamps <-> integer nanoseconds (exact) and seconds (durations, display)."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

pytest.importorskip("rclpy")
from builtin_interfaces.msg import Time

from transparency_ros.ros.conversions import ns_to_stamp, s_to_ns, stamp_to_ns, stamp_to_s


@given(
    sec=st.integers(min_value=-(2**31), max_value=2**31 - 1),
    nanosec=st.integers(min_value=0, max_value=999_999_999),
)
def test_stamps_round_trip_exactly_through_nanoseconds(sec: int, nanosec: int) -> None:
    stamp_ns = stamp_to_ns(Time(sec=sec, nanosec=nanosec))
    back = ns_to_stamp(stamp_ns)
    assert (back.sec, back.nanosec) == (sec, nanosec)


def test_a_stamp_of_this_decade_survives_where_float_seconds_do_not() -> None:
    stamp = Time(sec=1_800_000_000, nanosec=10_000_000)
    assert stamp_to_ns(stamp) == 1_800_000_000_010_000_000
    # float seconds, the old path, cannot hold it: the nearest float64 is 1800000000.0099999905
    assert int(stamp_to_s(stamp) * 1e9) != stamp_to_ns(stamp)
    assert ns_to_stamp(stamp_to_ns(stamp)) == stamp


def test_float_clock_readings_become_stamps_with_carry() -> None:
    assert s_to_ns(100.003) == 100_003_000_000
    assert s_to_ns(5.9999999999) == 6_000_000_000  # rounds up to a whole second
    assert divmod(s_to_ns(2.0**31 - 0.5), 1_000_000_000) == (2**31 - 1, 500_000_000)
