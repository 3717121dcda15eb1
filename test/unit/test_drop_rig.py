"""The drop-test rig environment: free fall, compliant contact, DAQ, on the one physics."""

from __future__ import annotations

import math

import pytest

from transparency_ros.core.actuator_physics import ActuatorPhysics, PhysicsParams
from transparency_ros.core.config import get_actuator
from transparency_ros.core.drop_rig import GRAVITY, DropRig, RigParams
from transparency_ros.core.errors import ModelError


def drop(actuator: str, height_m: float, seconds: float = 0.6, **rig: float) -> DropRig:
    env = DropRig(RigParams(shuttle_mass_kg=0.54, **rig))  # type: ignore[arg-type]
    physics = ActuatorPhysics(PhysicsParams.from_actuator(get_actuator(actuator)), env)
    env.release(height_m)
    for _ in range(round(seconds / 1e-3)):
        physics.advance(1e-3, lambda p, _v: 2.0 * (0.0 - p))  # k_s = 2 N m/rad about 0
    return env


def test_free_fall_then_contact_at_the_free_fall_time() -> None:
    env = drop("U10DD", 0.3, force_noise_n=0.0, height_noise_m=0.0)
    s = env.state
    assert s.first_contact_s == pytest.approx(math.sqrt(2 * 0.3 / GRAVITY), abs=2e-4)
    samples = env.daq
    assert len(samples) == pytest.approx(0.6 * 10_000, abs=2)  # 10 kHz grid
    assert samples[1].time_s - samples[0].time_s == pytest.approx(1e-4)
    before = [x for x in samples if x.time_s < s.first_contact_s - 1e-3]
    assert all(x.force_n == 0.0 for x in before)  # the load cell reads nothing in free fall
    assert max(x.force_n for x in samples) > 50.0  # a stiff contact: a large short force
    # the potentiometer follows free fall before contact
    x = before[-1]
    assert x.height_m == pytest.approx(0.3 - 0.5 * GRAVITY * x.time_s**2, abs=1e-6)


def test_rail_friction_makes_the_shuttle_arrive_later_and_slower() -> None:
    free = drop("U10DD", 0.3, force_noise_n=0.0, height_noise_m=0.0)
    braked = drop("U10DD", 0.3, force_noise_n=0.0, height_noise_m=0.0, rail_friction_n=1.0)
    assert free.state.first_contact_s is not None and braked.state.first_contact_s is not None
    assert braked.state.first_contact_s > free.state.first_contact_s + 0.005


def test_geared_actuators_bounce_and_the_noise_is_seeded() -> None:
    assert drop("U10GB", 0.3).state.contacts >= 2  # the paper's footnote: repeated bouncing
    a, b = drop("EC60", 0.1, seed=3), drop("EC60", 0.1, seed=3)
    assert [x.force_n for x in a.daq[:50]] == [x.force_n for x in b.daq[:50]]


def test_bad_rig_settings_are_refused() -> None:
    with pytest.raises(ModelError, match="shuttle_mass_kg"):
        RigParams(shuttle_mass_kg=0.0)
    with pytest.raises(ModelError, match="restitution"):
        RigParams(shuttle_mass_kg=0.5, restitution=1.5)
    with pytest.raises(ModelError, match="drop height"):
        DropRig(RigParams(shuttle_mass_kg=0.5)).release(-0.1)
