"""The feel -> process -> act state machine of Sec. 4 as a pure transition function.

    idle --start--> sweep --contact--> process --(t_process)--> act --(cage angle)--> caged
                      |                   |                       |
                      +----- lost (ball left the workspace, or the time budget ran out) ----+

* sweep: rotate CCW at 1 rev/s under the impedance controller (theta_d = theta_0 + w t);
* contact: the estimator's onset event; its stamp is t_e;
* process: the signal-processing time t_process (1 ms in the paper) before acting;
* act: rotate CW open loop at 10.5 V (:func:`open_loop_torque_nm`, the actuator's motor model)
  until the arm reaches the cage angle, which kinematically cages the ball.

Every trial ends with a :class:`TrialRecord`: the outcome in the paper's words (feel + cage,
feel, no detection) and t_feel, t_process, t_act, t_total against t_budget. Time is passed in.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from enum import Enum

from transparency_ros.core.config import ActuatorParams
from transparency_ros.core.errors import ModelError

ACT_VOLTAGE_V = 10.5
NOMINAL_VOLTAGE_V = 15.0


def open_loop_torque_nm(actuator: ActuatorParams, volts: float) -> float:
    """Drive torque of an open-loop voltage command at the output (positive: same sign as V).

    Stall torque k_m^2 w_0(V) with the no-load speed w_0 = 2 pi v_n V / 15 V, limited to the peak
    torque. The speed-dependent back-EMF part is in b_v (Table 1: b_v includes back-EMF drag),
    which the physics applies, so the free-running speed comes out as tau / b_v.
    """
    no_load = actuator.nominal_speed_at_15v_rad_s * abs(volts) / NOMINAL_VOLTAGE_V
    stall = actuator.motor_constant_nm_per_sqrt_w**2 * no_load
    return math.copysign(min(stall, actuator.peak_torque_nm), volts)


class Phase(str, Enum):
    IDLE = "idle"
    SWEEP = "sweep"
    PROCESS = "process"
    ACT = "act"
    CAGED = "caged"
    LOST = "lost"


class Outcome(str, Enum):
    FEEL_AND_CAGE = "feel + cage"
    FEEL = "feel"
    NO_DETECTION = "no detection"


@dataclass(frozen=True)
class FeelCageConfig:
    sweep_speed_rad_s: float = 2.0 * math.pi  # CCW, 1 rev/s
    act_torque_nm: float = -1.0  # CW; from open_loop_torque_nm(actuator, -10.5)
    cage_position_rad: float = -math.pi / 2  # absolute angle that cages the ball
    process_time_s: float = 0.001
    budget_s: float = math.inf  # contact -> caged, when no ground truth tells a lost ball

    def __post_init__(self) -> None:
        if not (self.sweep_speed_rad_s > 0 and self.act_torque_nm < 0):
            raise ModelError("the sweep turns CCW (speed > 0) and the act CW (torque < 0)")
        if not (self.process_time_s >= 0 and self.budget_s > 0):
            raise ModelError("process time must be >= 0 and the budget > 0")


@dataclass(frozen=True)
class TrialRecord:
    outcome: Outcome
    t_feel_s: float | None  # t_e - t_t (needs the true contact time)
    t_process_s: float | None
    t_act_s: float | None
    t_total_s: float | None
    t_budget_s: float | None  # time from contact until the ball left the workspace


@dataclass(frozen=True)
class BehaviorState:
    phase: Phase = Phase.IDLE
    start_s: float = 0.0
    start_position_rad: float = 0.0
    detected_s: float | None = None  # t_e: stamp of the onset event
    act_start_s: float | None = None
    done_s: float | None = None


@dataclass(frozen=True)
class Sweep:
    position_rad: float
    velocity_rad_s: float


@dataclass(frozen=True)
class Torque:
    torque_nm: float


@dataclass(frozen=True)
class Hold:
    position_rad: float


Command = Sweep | Torque | Hold


def start(now_s: float, position_rad: float) -> BehaviorState:
    return BehaviorState(Phase.SWEEP, now_s, position_rad)


def on_contact(state: BehaviorState, stamp_s: float) -> BehaviorState:
    """The estimator's onset event (stamp = t_e). Only the first one during the sweep counts."""
    if state.phase is not Phase.SWEEP:
        return state
    return replace(state, phase=Phase.PROCESS, detected_s=stamp_s)


def step(
    state: BehaviorState,
    config: FeelCageConfig,
    now_s: float,
    position_rad: float,
    *,
    ball_lost: bool = False,
    position_s: float | None = None,
) -> tuple[BehaviorState, Command | None]:
    """Advance with the current time and arm position; return the command to send now.

    ``position_s``: when the position was measured (default ``now_s``); the cage closed then,
    not when this step got to see it, so ``done_s`` of a caged trial is that time."""
    phase = state.phase
    if phase in (Phase.IDLE, Phase.CAGED, Phase.LOST):
        return state, (Hold(position_rad) if phase is Phase.CAGED else None)
    over_budget = state.detected_s is not None and now_s - state.detected_s > config.budget_s
    if ball_lost or over_budget:
        return replace(state, phase=Phase.LOST, done_s=now_s), None
    if (
        phase is Phase.PROCESS
        and state.detected_s is not None
        and now_s - state.detected_s >= config.process_time_s
    ):
        state, phase = replace(state, phase=Phase.ACT, act_start_s=now_s), Phase.ACT
    if phase is Phase.ACT:
        if position_rad <= config.cage_position_rad:
            closed = now_s if position_s is None else min(now_s, position_s)
            closed = max(closed, state.act_start_s or closed)
            return replace(state, phase=Phase.CAGED, done_s=closed), Hold(position_rad)
        return state, Torque(config.act_torque_nm)
    elapsed = now_s - state.start_s
    return state, Sweep(
        state.start_position_rad + config.sweep_speed_rad_s * elapsed, config.sweep_speed_rad_s
    )


def record(state: BehaviorState, contact_s: float | None, lost_s: float | None) -> TrialRecord:
    """Summarise a finished trial; ``contact_s`` (t_t) and ``lost_s`` come from ground truth."""
    if state.detected_s is None:
        outcome = Outcome.NO_DETECTION
    elif state.phase is Phase.CAGED:
        outcome = Outcome.FEEL_AND_CAGE
    else:
        outcome = Outcome.FEEL
    t_feel = (
        state.detected_s - contact_s
        if state.detected_s is not None and contact_s is not None
        else None
    )
    t_process = (
        state.act_start_s - state.detected_s
        if state.act_start_s is not None and state.detected_s is not None
        else None
    )
    t_act = (
        state.done_s - state.act_start_s
        if state.act_start_s is not None and state.done_s is not None and state.phase is Phase.CAGED
        else None
    )
    parts = (t_feel, t_process, t_act)
    total = sum(p for p in parts if p is not None) if all(p is not None for p in parts) else None
    budget = lost_s - contact_s if lost_s is not None and contact_s is not None else None
    return TrialRecord(outcome, t_feel, t_process, t_act, total, budget)
