"""Pairing samples with the driver's setpoints by stamp (core.setpoint_join), and the estimator
using them (core.estimator)."""

from __future__ import annotations

import math

import pytest

from transparency_ros.core.estimator import EstimatorPipeline, SampleRejectedError
from transparency_ros.core.setpoint_join import SetpointJoin, StateSample

MS = 1_000_000


def state(stamp_ms: int, names: tuple[str, ...] = ("a",), position: float = 0.0) -> StateSample:
    return StateSample(stamp_ms * MS, list(names), [position] * len(names), [0.0] * len(names))


def stamps(ready: list) -> list[int]:
    return [p.sample.stamp_ns // MS for p in ready]


def at(stamp_ms: float) -> float:
    """Arrival time [s] of a message stamped ``stamp_ms`` (delivered at once)."""
    return stamp_ms * 1e-3


def test_a_source_without_setpoints_waits_once_then_passes_straight_on() -> None:
    join = SetpointJoin(max_wait_s=0.02, first_wait_s=0.5)  # none expected
    assert join.sample(state(1), at(1)) == []  # a setpoint may yet come (discovery)
    assert join.expire(at(400)) == []
    ready = join.expire(at(502))
    assert stamps(ready) == [1] and ready[0].setpoints is None and not ready[0].missing
    assert join.unpaired == {"a"} and not join.active
    assert join.take_news() == (["a"], [])
    ready = join.sample(state(600), at(600))
    assert stamps(ready) == [600] and join.missing == 0


def test_a_setpoint_publisher_being_matched_is_waited_for_longer() -> None:
    join = SetpointJoin(first_wait_s=0.5, expected_wait_s=5.0)
    join.expected = True  # the caller sees a /joint_setpoints publisher not heard yet
    assert join.sample(state(1), at(1)) == []
    assert join.expire(at(3000)) == []
    ready = join.setpoint(1 * MS, ["a"], [0.7], [0.0], at(3001))
    assert stamps(ready) == [1] and ready[0].setpoints == {"a": (0.7, 0.0)}


def test_setpoint_before_or_after_its_sample_is_matched_in_order() -> None:
    join = SetpointJoin()
    assert join.setpoint(1 * MS, ["a"], [0.5], [0.0], at(1)) == []
    ready = join.sample(state(1), at(1))
    assert stamps(ready) == [1] and ready[0].setpoints == {"a": (0.5, 0.0)}
    # the sample first: held until its setpoint comes
    assert join.sample(state(2), at(2)) == []
    assert join.sample(state(3), at(3)) == []
    ready = join.setpoint(2 * MS, ["a"], [0.6], [0.1], at(3))
    assert stamps(ready) == [2] and ready[0].setpoints == {"a": (0.6, 0.1)}
    ready = join.setpoint(3 * MS, ["a"], [0.7], [0.0], at(3))
    assert stamps(ready) == [3] and ready[0].setpoints == {"a": (0.7, 0.0)}
    assert join.matched == 3 and join.missing == 0


def test_a_lost_setpoint_is_released_as_missing_when_a_later_one_comes() -> None:
    join = SetpointJoin()
    join.setpoint(1 * MS, ["a"], [0.5], [0.0], at(1))
    join.sample(state(1), at(1))
    assert join.sample(state(2), at(2)) == []  # its setpoint is lost on the way
    ready = join.setpoint(3 * MS, ["a"], [0.5], [0.0], at(3))  # a later one: 2's is lost
    ready += join.sample(state(3), at(3))
    assert stamps(ready) == [2, 3]
    assert ready[0].missing and ready[0].setpoints == {"a": (0.5, 0.0)}  # the nearest, 1's
    assert ready[1].setpoints == {"a": (0.5, 0.0)}
    assert (join.matched, join.missing) == (2, 1)


def test_samples_from_before_the_setpoint_stream_was_heard_take_its_first() -> None:
    """At start-up the state stream may be matched before the setpoint stream: the samples
    before the first setpoint heard take it, not a stale (or no) command."""
    join = SetpointJoin()
    assert join.sample(state(1), at(1)) == [] and join.sample(state(2), at(2)) == []
    ready = join.setpoint(3 * MS, ["a"], [0.7], [0.0], at(3)) + join.sample(state(3), at(3))
    assert stamps(ready) == [1, 2, 3]
    assert all(p.setpoints == {"a": (0.7, 0.0)} and not p.missing for p in ready)
    assert (join.before_first, join.missing, join.matched) == (2, 0, 1)
    assert join.take_news() == ([], [])


def test_a_lost_setpoint_is_released_after_the_wait() -> None:
    join = SetpointJoin(max_wait_s=0.02)
    join.setpoint(1 * MS, ["a"], [0.5], [0.0], at(1))
    join.sample(state(1), at(1))
    assert join.sample(state(2), at(2)) == []
    assert join.expire(at(21)) == []
    ready = join.expire(at(23))
    assert stamps(ready) == [2] and ready[0].missing
    assert join.take_news() == ([], [])  # one lost setpoint is no stopped stream


def test_a_source_without_setpoints_beside_one_with_them() -> None:
    """Two drivers: one publishes setpoints (joint a), the other not (joint b)."""
    join = SetpointJoin(max_wait_s=0.005, first_wait_s=0.01)
    released: list = []
    for t in range(1, 40):
        released += join.setpoint(t * MS, ["a"], [0.1], [0.0], at(t))
        released += join.sample(state(t, ("a",)), at(t))
        released += join.sample(StateSample(t * MS + 300_000, ["b"], [0.0], [0.0]), at(t + 0.3))
    assert "b" in join.unpaired and "a" not in join.unpaired
    order = [p.sample.stamp_ns for p in released]
    assert order == sorted(order)  # first in, first out
    assert all(p.setpoints is None and not p.missing for p in released if p.sample.names == ["b"])
    assert all(p.setpoints is not None for p in released if p.sample.names == ["a"])
    assert join.missing == 0
    assert len(join.sample(StateSample(50 * MS, ["b"], [0.0], [0.0]), at(50))) == 1


def test_setpoints_that_stop_are_reported_once() -> None:
    join = SetpointJoin(max_wait_s=0.005, first_wait_s=0.1)
    for t in range(1, 5):
        join.setpoint(t * MS, ["a"], [0.1], [0.0], at(t))
        join.sample(state(t), at(t))
    ready: list = []
    for t in range(5, 200):  # the driver restarted without setpoints
        ready += join.sample(state(t), at(t))
    assert join.take_news() == ([], ["a"]) and join.take_news() == ([], [])
    assert "a" in join.unpaired and join.missing > 0
    assert len(join.sample(state(300), at(300))) >= 1  # no longer held back


def test_bad_setpoints_are_refused_with_the_joint() -> None:
    join = SetpointJoin()
    for positions, velocities, text in (
        ([math.inf], [0.0], "a: setpoint inf"),
        ([0.1], [math.nan], "a: setpoint 0.1, nan"),
        ([0.1, 0.2], [], "2 positions, 0 velocities for 1 names"),
    ):
        with pytest.raises(ValueError, match=text):
            join.setpoint(1, ["a"], positions, velocities, 0.0)
    # NaN position: the motor was not held (NaN velocity then too: not driven)
    assert join.setpoint(1, ["a"], [math.nan], [math.nan], 0.0) == []


def test_the_estimate_uses_the_setpoint_not_a_stale_command() -> None:
    """The issue's case: the estimator holds an old command, the driver moved on."""
    pipeline = EstimatorPipeline()
    pipeline.command(["a"], [0.0], [])  # the old target; the new one never reached us
    estimates, _ = pipeline.sample(1 * MS, ["a"], [1.0], [], {"a": (1.0, 0.0)})
    assert estimates[0].error_rad == 0.0 and estimates[0].torque_nm == 0.0
    assert pipeline.theta_d_gap == {"a": 1.0}
    estimates, _ = pipeline.sample(2 * MS, ["a"], [1.0], [])  # without: the command's
    assert estimates[0].error_rad == -1.0


def test_a_joint_the_driver_did_not_hold_gets_no_estimate() -> None:
    pipeline = EstimatorPipeline()
    setpoints = {"a": (math.nan, math.nan), "b": (0.02, 0.0)}
    estimates, events = pipeline.sample(1 * MS, ["a", "b"], [5.0, 0.0], [], setpoints)
    assert [e.joint for e in estimates] == ["b"] and events == []  # a's 5 rad is no contact
    assert pipeline.not_driven == 1 and pipeline.samples == 1


def test_a_pure_torque_command_leaves_the_joint_without_an_estimate() -> None:
    """The feel-cage's act phase drives the arm by torque alone (no positions, an effort): the
    estimator takes it (it was refused, with a warning), and without setpoints the joint gets
    no estimate from the older position command until the next one, as a NaN setpoint says."""
    pipeline = EstimatorPipeline()
    pipeline.command(["a"], [0.0], [])
    pipeline.command(["a"], [], [], efforts=[-1.5])
    estimates, events = pipeline.sample(1 * MS, ["a"], [2.0], [])  # 2 rad from the old target
    assert estimates == [] and events == [] and pipeline.not_driven == 1
    pipeline.command(["a"], [2.0], [])
    estimates, _ = pipeline.sample(2 * MS, ["a"], [2.0], [])
    assert estimates[0].error_rad == 0.0
    with pytest.raises(SampleRejectedError):  # neither positions nor efforts
        pipeline.command(["a"], [], [])
    with pytest.raises(SampleRejectedError):
        pipeline.command(["a"], [], [], efforts=[math.inf])
