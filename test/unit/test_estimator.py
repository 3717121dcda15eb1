"""Eq. (1), the Schmitt-trigger detector, the threshold helper and the momentum observer."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from transparency_ros.core.actuator_physics import (
    ActuatorPhysics,
    ImpedanceLaw,
    InertialLoad,
    PhysicsParams,
)
from transparency_ros.core.config import get_actuator
from transparency_ros.core.estimator import (
    ContactEvent,
    ContactLevel,
    DetectorSettings,
    EstimatorError,
    EstimatorGains,
    EstimatorPipeline,
    EventKind,
    SampleRejectedError,
    SchmittDetector,
    estimate_torque,
    propose_thresholds,
)
from transparency_ros.core.momentum_observer import FrictionModel, MomentumObserver


def test_eq1_and_the_full_estimate() -> None:
    gains = EstimatorGains(2.0)
    assert gains.torque(0.1, 0.0) == pytest.approx(0.2)
    full = EstimatorGains(2.0, 0.5, 0.1)
    assert full.torque(0.1, 0.0, 1.0, 2.0) == pytest.approx(0.2 + 0.5 * (1 - 2) - 0.1 * 2)
    arr = estimate_torque(full, [0.1, 0.2], [0.0, 0.0], [1.0, 0.0], [2.0, 0.0])
    assert arr.tolist() == pytest.approx([full.torque(0.1, 0, 1, 2), full.torque(0.2, 0, 0, 0)])
    with pytest.raises(EstimatorError, match="k_s_nm_per_rad must be > 0"):
        EstimatorGains(0.0).validated()


MS = 1_000_000  # ns
S = 1_000_000_000  # ns


def feed(det: SchmittDetector, values: list[float], dt_ns: int = MS, joint: str = "j",
         start_ns: int = 0) -> list[tuple[int, ContactEvent]]:  # fmt: skip
    out = []
    for i, v in enumerate(values):
        for ev in det.update(joint, start_ns + i * dt_ns, v, 2.0 * v):
            out.append((i, ev))
    return out


def test_onset_is_stamped_at_the_crossing_sample_even_with_a_dwell() -> None:
    det = SchmittDetector(DetectorSettings(0.1, 0.05, onset_dwell_s=0.003))
    events = feed(det, [0.0, 0.05, 0.11, 0.12, 0.13, 0.14, 0.2])
    ((i, ev),) = events
    assert ev.kind is EventKind.CONTACT_ONSET and ev.stamp_ns == 2 * MS
    assert i == 5 and ev.confirmed_ns == 5 * MS
    assert det.level("j") is ContactLevel.CONTACT


def test_a_blip_shorter_than_the_dwell_is_ignored() -> None:
    det = SchmittDetector(DetectorSettings(0.1, 0.05, onset_dwell_s=0.003))
    assert feed(det, [0.2, 0.2, 0.0, 0.0, 0.2, 0.0]) == []


def test_hysteresis_and_release_dwell() -> None:
    det = SchmittDetector(DetectorSettings(0.1, 0.05, release_dwell_s=0.002))
    events = feed(det, [0.2, 0.08, 0.09, 0.04, 0.04, 0.2, 0.04, 0.04, 0.04])
    kinds = [(i, ev.kind) for i, ev in events]
    # 0.08 and 0.09 stay in contact (above release); the 0.2 at i=5 interrupts the 2 ms below
    # 0.05 that release needs, so release comes at i=8, stamped where that run began (i=6)
    assert kinds == [(0, EventKind.CONTACT_ONSET), (8, EventKind.RELEASE)]
    assert events[1][1].stamp_ns == 6 * MS
    det.reset()
    events = feed(det, [0.2, 0.04, 0.04, 0.04])
    assert [ev.kind for _, ev in events] == [EventKind.CONTACT_ONSET, EventKind.RELEASE]
    assert events[1][1].stamp_ns == 1 * MS  # the first sample below the level


def test_two_levels() -> None:
    det = SchmittDetector(DetectorSettings(0.1, 0.05, collision_onset=0.3, collision_release=0.2))
    events = feed(det, [0.5, 0.25, 0.15, 0.02])
    assert [ev.kind for _, ev in events] == [
        EventKind.CONTACT_ONSET,
        EventKind.COLLISION_ONSET,
        EventKind.COLLISION_RELEASE,
        EventKind.RELEASE,
    ]
    assert events[1][1].level is ContactLevel.COLLISION


def test_bias_per_joint_settings_runtime_changes_and_validation() -> None:
    det = SchmittDetector(DetectorSettings(0.1, 0.05), {"knee": DetectorSettings(0.3, 0.1)})
    assert feed(det, [0.2], joint="knee") == []
    assert len(feed(det, [0.2], joint="hip")) == 1
    det.configure("hip", bias=0.5)  # a steady error of 0.5 rad is no contact
    det.reset("hip")
    assert feed(det, [0.55, 0.45], joint="hip") == []
    with pytest.raises(EstimatorError, match="contact_release must satisfy"):
        det.configure("hip", contact_release=0.2)
    assert det.settings_for("hip").contact_release == 0.05  # refused change not applied
    with pytest.raises(EstimatorError, match="collision_onset"):
        DetectorSettings(0.1, 0.05, collision_onset=0.05).validated()


def test_threshold_proposal_follows_the_paper() -> None:
    rng = np.random.default_rng(1)
    quiet = 0.02 + 0.003 * np.sin(np.linspace(0, 20, 2000)) + rng.normal(0, 1e-5, 2000)
    prop = propose_thresholds(quiet, k_s_nm_per_rad=2.0)
    assert prop.steady_error_rad == pytest.approx(0.023, abs=2e-4)
    assert prop.epsilon_rad == pytest.approx(0.01)  # k_s eps = 0.02 N m
    assert prop.contact_onset_rad == pytest.approx(prop.steady_error_rad + 0.01)
    assert prop.contact_release_rad < prop.contact_onset_rad < prop.collision_onset_rad
    noisy = propose_thresholds(rng.normal(0, 0.01, 2000), k_s_nm_per_rad=2.0)
    assert noisy.epsilon_rad == pytest.approx(5 * noisy.noise_std_rad)
    with pytest.raises(EstimatorError, match=">= 10 finite"):
        propose_thresholds([0.0, math.nan] * 6, 2.0)


def test_momentum_observer_tracks_an_external_torque_step() -> None:
    act = get_actuator("EC60")
    torque_ext = 0.3
    load = InertialLoad(6.5e-5, lambda _p, _v, t: torque_ext if t >= 0.2 else 0.0)
    params = PhysicsParams.from_actuator(act)
    physics = ActuatorPhysics(params, load)
    model = FrictionModel.from_actuator(act, 6.5e-5)
    observer = MomentumObserver(model, gain_per_s=100.0)
    law = ImpedanceLaw(2.0, 0.0, 0.0, 0.0, 0.0)
    residuals = []
    t = 0.0
    for _ in range(600):
        physics.advance(0.001, law)
        t += 0.001
        residuals.append(
            observer.update(t, physics.velocity_rad_s, physics.state.applied_torque_nm)
        )
    before, after = np.array(residuals[150:195]), np.array(residuals[300:])
    assert np.all(np.abs(before) < 0.02)
    # the shaft moves once 0.3 N m beats static friction: the residual settles near tau_ext
    assert np.median(after) == pytest.approx(torque_ext, rel=0.15)
    with pytest.raises(EstimatorError, match="stamps must increase"):
        observer.update(t, 0.0, 0.0)


def test_comparison_on_the_same_data() -> None:
    """While the joint moves, the observer (given the true friction model) catches pulses the
    position-error threshold, which must cover the tracking error, misses."""
    from transparency_ros.analysis.estimator_comparison import compare  # noqa: PLC0415

    position, observer = compare("EC60", 100.0, pulses=12, amplitude_rad=0.3)
    assert position.unit == "rad" and observer.unit == "N m"
    assert len(position.delays_s) + position.misses == 12
    assert len(observer.delays_s) > len(position.delays_s)
    assert observer.median_delay_s < 0.02
    assert all(0 <= d <= 0.03 for d in position.delays_s + observer.delays_s)


def test_a_sample_is_taken_whole_or_not_at_all() -> None:
    """Two joints, the second overflowing tau_hat: rejected, and the first joint's state (its
    last stamp, its detector) is not touched either."""
    pipeline = EstimatorPipeline()
    with pytest.raises(SampleRejectedError, match="overflows"):
        pipeline.sample(S, ["a", "b"], [-0.5, 1e308], [])
    assert pipeline.rejected == {"out_of_range": 1} and pipeline.samples == 0
    estimates, events = pipeline.sample(S, ["a", "b"], [-0.5, 0.0], [])  # same stamp: fine
    assert [e.joint for e in estimates] == ["a", "b"] and [e.joint for e in events] == ["a"]


_values = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.0, 0.09, 0.11, -0.2, 1e308, -1e308]),
)
_samples = st.lists(
    st.tuples(
        st.one_of(
            st.integers(-(2**63), 2**63 - 1),
            st.sampled_from([0, 1, 2**31 * S - 1, 2**31 * S, 2**31 * S + 1]),
        ),
        st.lists(st.sampled_from(["a", "b", "x"]), max_size=3),
        st.lists(_values, max_size=3),
        st.lists(_values, max_size=3),
    ),
    max_size=60,
)


@settings(max_examples=300, deadline=None)
@given(_samples)
def test_any_stream_of_samples_is_taken_or_rejected_and_counted(
    stream: list[tuple[int, list[str], list[float], list[float]]],
) -> None:
    """Whatever arrives: no exception but a counted rejection; every sample either taken or
    rejected; events only from taken samples, their stamps increasing per joint, and the
    contact state alternating onset / release."""
    pipeline = EstimatorPipeline(joints=frozenset({"a", "b"}))
    pipeline.detector = SchmittDetector(DetectorSettings(0.1, 0.05))
    taken: dict[str, list[int]] = {}
    events: dict[str, list[ContactEvent]] = {}
    for stamp, names, positions, velocities in stream:
        try:
            estimates, new = pipeline.sample(stamp, names, positions, velocities)
        except SampleRejectedError:
            continue
        assert all(math.isfinite(e.torque_nm) and math.isfinite(e.error_rad) for e in estimates)
        for name in names:
            taken.setdefault(name, []).append(stamp)
        for event in new:
            assert event.stamp_ns == stamp
            events.setdefault(event.joint, []).append(event)
    assert pipeline.samples + sum(pipeline.rejected.values()) == len(stream)
    for stamps in taken.values():
        assert all(b > a for a, b in itertools.pairwise(stamps))
    for joint_events in events.values():
        kinds = [e.kind for e in joint_events]
        assert kinds[::2] == [EventKind.CONTACT_ONSET] * len(kinds[::2])
        assert kinds[1::2] == [EventKind.RELEASE] * len(kinds[1::2])
