"""Feel -> process -> act: the transition function, the motor model and Table 2."""

from __future__ import annotations

import dataclasses
import math

import pytest

from transparency_ros.analysis import feelcage_sim as sim
from transparency_ros.core import feel_cage as fc
from transparency_ros.core.ball_on_rail import Ball, RailGeometry
from transparency_ros.core.config import get_actuator
from transparency_ros.core.errors import ModelError

CONFIG = fc.FeelCageConfig(act_torque_nm=-2.0, cage_position_rad=-1.0, process_time_s=0.001)


def test_open_loop_torque_from_the_motor_model() -> None:
    u10dd = get_actuator("U10DD")
    stall = 0.285**2 * 2 * math.pi * 25.0 * 10.5 / 15.0  # k_m^2 w_0(10.5 V) = 8.93 N m
    assert stall > u10dd.peak_torque_nm
    assert fc.open_loop_torque_nm(u10dd, -10.5) == -u10dd.peak_torque_nm
    t2822 = get_actuator("T2822")
    assert fc.open_loop_torque_nm(t2822, 10.5) == pytest.approx(
        min(0.617**2 * 2 * math.pi * 8.99 * 0.7, 11.44)
    )


def test_sweep_process_act_caged() -> None:
    state = fc.start(0.0, 0.5)
    state, cmd = fc.step(state, CONFIG, 0.25, 2.0)
    assert cmd == fc.Sweep(0.5 + 2 * math.pi * 0.25, 2 * math.pi)
    state = fc.on_contact(state, 0.300)
    assert state.phase is fc.Phase.PROCESS and state.detected_s == 0.300
    assert fc.on_contact(state, 0.305).detected_s == 0.300  # only the first onset counts
    state, cmd = fc.step(state, CONFIG, 0.3005, 2.3)  # still processing: keep sweeping
    assert state.phase is fc.Phase.PROCESS and isinstance(cmd, fc.Sweep)
    state, cmd = fc.step(state, CONFIG, 0.301, 2.3)
    assert state.phase is fc.Phase.ACT and cmd == fc.Torque(-2.0)
    state, cmd = fc.step(state, CONFIG, 0.340, -1.01)
    assert state.phase is fc.Phase.CAGED and cmd == fc.Hold(-1.01)
    rec = fc.record(state, contact_s=0.295, lost_s=None)
    assert rec.outcome is fc.Outcome.FEEL_AND_CAGE
    assert (rec.t_feel_s, rec.t_process_s, rec.t_act_s) == pytest.approx((0.005, 0.001, 0.039))
    assert rec.t_total_s == pytest.approx(0.045) and rec.t_budget_s is None


def test_the_cage_closes_when_the_sample_was_taken_not_when_it_was_seen() -> None:
    acting = fc.step(fc.on_contact(fc.start(0.0, 0.0), 0.3), CONFIG, 0.301, 1.0)[0]
    state, _ = fc.step(acting, CONFIG, 0.345, -1.01, position_s=0.340)
    assert state.phase is fc.Phase.CAGED and state.done_s == 0.340
    # a stamp from the future or from before the act started is not believed
    assert fc.step(acting, CONFIG, 0.345, -1.01, position_s=0.350)[0].done_s == 0.345
    assert fc.step(acting, CONFIG, 0.345, -1.01, position_s=0.2)[0].done_s == 0.301


def test_lost_before_and_after_detection() -> None:
    state = fc.start(0.0, 0.0)
    state, _ = fc.step(state, CONFIG, 0.1, 0.6, ball_lost=True)
    assert fc.record(state, 0.05, 0.1).outcome is fc.Outcome.NO_DETECTION
    state = fc.on_contact(fc.start(0.0, 0.0), 0.2)
    state, _ = fc.step(state, CONFIG, 0.25, 1.0, ball_lost=True)
    rec = fc.record(state, 0.19, 0.25)
    assert rec.outcome is fc.Outcome.FEEL and rec.t_act_s is None
    assert rec.t_budget_s == pytest.approx(0.06)
    budgeted = dataclasses.replace(CONFIG, budget_s=0.01)
    state, _ = fc.step(fc.on_contact(fc.start(0.0, 0.0), 0.2), budgeted, 0.22, 1.0)
    assert state.phase is fc.Phase.LOST  # time budget exceeded


def test_config_and_model_validation() -> None:
    with pytest.raises(ModelError, match="CW"):
        fc.FeelCageConfig(act_torque_nm=1.0)
    with pytest.raises(ModelError, match="restitution"):
        Ball("x", 0.1, 0.05, 1.5, 0.01, 1e4)
    with pytest.raises(ModelError, match="exit must lie within"):
        RailGeometry(0.1, 0.0, 0.0, 0.2, 1.0)


def test_table2_comes_out_as_the_paper_reports_it() -> None:
    """One geometry and one set of ball parameters (config/feel_cage.yaml) for all 12 cells."""
    setup = sim.load_setup()
    results = sim.table2(setup)
    for ball, row in sim.PAPER_TABLE2.items():
        got = tuple(results[(ball, a)].outcome.value for a in sim.ACTUATORS)
        assert got == row, ball
    # and every outcome has its physical reason in the timings
    for (ball, actuator), r in results.items():
        needed = sim.time_to_cage(actuator, setup)
        if r.outcome is fc.Outcome.FEEL_AND_CAGE:
            assert r.t_total_s is not None
            assert r.t_budget_s is None or r.t_total_s < r.t_budget_s
        elif r.outcome is fc.Outcome.FEEL:
            assert r.t_feel_s is not None and r.t_budget_s is not None
            assert r.t_feel_s + setup.process_time_s + needed > r.t_budget_s, (ball, actuator)
        else:
            assert r.t_feel_s is None and r.t_budget_s is not None  # the ball left first


def test_without_the_friction_ripple_two_geared_cells_detect() -> None:
    """What the model leaves out matters: constant friction makes e_s the mean error, and the
    geared actuators then feel balls the paper's could not."""
    setup = dataclasses.replace(sim.load_setup(), friction_ripple=0.0)
    results = sim.table2(setup)
    assert results[("lacrosse", "T2822")].outcome is fc.Outcome.FEEL
    assert results[("bocce", "U10GB")].outcome is fc.Outcome.FEEL
