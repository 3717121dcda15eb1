"""The drop-test integrator of the discrepancy tool, compiled (numba).

One row is one trial under one physics: the fits simulate every trial for every candidate
value at once, hundreds of rows per call and hundreds of calls per analysis. A row is a scalar
state (motor, arm, shuttle) stepped with plain branches; numba compiles the loop (cached on
disk after the first run), which is what makes a fixed small step affordable for every row.

The physics (see :mod:`transparency_ros.analysis.discrepancy.drop` for which effect changes
which value):

* motor and arm are one body under the impedance k_s (theta_d - theta_sensed), the offset,
  viscous drag integrated exactly over the step and Karnopp stick-slip friction with any
  reversal located within the step; with backlash they part whenever the motor would have to
  pull the arm, and rejoin (momentum kept) when the gap closes;
* the shuttle falls under gravity and rail friction; a collision is located within the step,
  momentum is exchanged there with restitution e (a rebound slower than 5 cm/s ends the
  bouncing: the shuttle stays on the arm), and the rest of the step is integrated from the new
  velocities; up to four collisions per step;
* with a finite contact stiffness the contact is a spring-damper instead (damped for e);
* the shuttle's weight loads the arm while they touch; the controller sees the encoder's lattice;
* the motor's cogging, a wave in its true position, adds to the drive's torque;
* a torsional spring (and damper) between motor and arm makes them two bodies (a compliant
  hub, shaft or arm): the encoder reads the motor's side; with backlash the spring acts
  through the dead band (in series).
"""

from __future__ import annotations

import math
from typing import Any

import numba
import numpy as np

from transparency_ros.core.compiled import jit, parallel_jit

GRAVITY = 9.81
GLUE_SPEED_M_S = 0.05  # a bounce slower than this ends the bouncing
MAX_STRIKES = 4  # collisions located within one step
CONTACT_MARGIN_M = 1e-5  # a gap this small counts as contact to come (arm and shuttle accelerate)


# columns of the physics matrix of :func:`impact`, one row per simulated trial
COLUMNS = (
    "mass",  # shuttle [kg]
    "arm",  # arm length r [m]
    "k_s",
    "theta_d",
    "arm_inertia",
    "q0",  # motor position at the start [rad]
    "y0",  # shuttle height and velocity at the start
    "v0",
    "rotor",  # J_r
    "viscous",
    "coulomb",
    "static",
    "offset",
    "weight",  # m_s g r while touching
    "e",  # restitution
    "stiffness",  # contact spring [N/m]; inf: instant collisions
    "damping",  # contact damper [N s/m]
    "rail",  # rail friction [N]
    "backlash",
    "encoder_step",
    "substeps",  # integration steps per output step
    "contact_substeps",  # the same while a contact spring is (about to be) compressed
    "limit",  # the drive's impedance torque is clipped here [N m] (inf: no saturation)
    "cogging",  # the motor's cogging torque A sin(N q + phase) at its true position: A [N m]
    "cogging_periods",  # N: periods per revolution of the output
    "cogging_phase",  # phase [rad], in the model's sense of q
    "torsion",  # a torsional spring between motor and arm [N m/rad] (0: rigid)
    "torsion_damping",  # its damper [N m s/rad]
    "backlash_start",  # the arm's start in the dead band, arm - motor in half bands (+1: the
    # far flank from the strike, the whole band to close; -1: on the flank the strike loads)
    "steps",  # output steps this row needs (its own trial's length; 0: all, no shortcuts)
)
(
    MASS,
    ARM,
    K_S,
    THETA_D,
    ARM_INERTIA,
    Q0,
    Y0,
    V0,
    ROTOR,
    VISCOUS,
    COULOMB,
    STATIC,
    OFFSET,
    WEIGHT,
    E,
    STIFFNESS,
    DAMPING,
    RAIL,
    BACKLASH,
    ENCODER_STEP,
    SUBSTEPS,
    CONTACT_SUBSTEPS,
    LIMIT,
    COGGING,
    COGGING_PERIODS,
    COGGING_PHASE,
    TORSION,
    TORSION_DAMPING,
    BACKLASH_START,
    ROW_STEPS,
) = range(len(COLUMNS))


@jit
def sign(x: float) -> float:
    return 1.0 if x > 0.0 else -1.0 if x < 0.0 else 0.0


@jit
def drag_step(w: float, accel: float, rate: float, dt: float) -> tuple[float, float]:
    """(velocity, displacement) after ``dt`` of w' = accel - rate w, exactly."""
    x = rate * dt
    if x < 1e-6:
        phi1, phi2 = 1.0 - x / 2, 0.5 - x / 6
    else:
        decay = math.exp(-x)
        phi1, phi2 = (1.0 - decay) / x, (x - 1.0 + decay) / (x * x)
    return w * math.exp(-x) + accel * dt * phi1, (w * phi1 + accel * dt * phi2) * dt


@jit
def friction_step(
    w: float,
    inertia: float,
    torque: float,
    dt: float,
    friction: tuple[float, float, float],
) -> tuple[float, float]:
    """(new velocity, mean velocity over the step) of a body under ``torque`` with viscous drag
    and Karnopp stick-slip friction (``friction``: b_v, tau_coul, breakaway torque). A reversal
    within the step is located: the body stops there and, if the torque breaks the static
    friction, moves the other way for the rest of it."""
    viscous, coulomb, static = friction
    if w == 0.0 and abs(torque) <= static:
        return 0.0, 0.0
    rate = viscous / inertia
    direction = sign(torque) if w == 0.0 else sign(w)
    new, moved = drag_step(w, (torque - coulomb * direction) / inertia, rate, dt)
    if w != 0.0 and new * w < 0.0:
        t0 = dt * w / (w - new)  # the (linear) zero crossing
        moved = 0.5 * w * t0
        new = 0.0
        if abs(torque) > static:
            back = (torque - coulomb * sign(torque)) / inertia
            new, more = drag_step(0.0, back, rate, max(dt - t0, 0.0))
            moved += more
    return new, (moved / dt if dt > 0.0 else w)


@jit
def sense(q: float, step: float) -> float:
    """The position the controller sees: on the encoder's lattice."""
    return round(q / step) * step if step > 0.0 else q


@jit
def drive_torque(row: Any, q: float, w: float, dt: float) -> float:
    """The motor's torque at motor position ``q`` (speed ``w``): the impedance at the step's
    midpoint (predicted: held at the step's start it would lag by half a step, a steady error
    in the swing) on the sensed position, clipped at the drive's limit, then the offset and the
    cogging at the motor's true position (neither passes through the controller)."""
    impedance = row[K_S] * (row[THETA_D] - sense(q, row[ENCODER_STEP]) - 0.5 * w * dt)
    limit = row[LIMIT]
    torque = min(max(impedance, -limit), limit) + row[OFFSET]
    if row[COGGING] != 0.0:
        wave = row[COGGING_PERIODS] * (q + 0.5 * w * dt) + row[COGGING_PHASE]
        torque += row[COGGING] * math.sin(wave)
    return float(torque)


@jit
def same_bits(a: Any, b: Any, n: int) -> bool:
    """Whether the first ``n`` values of two states are the same to the bit (a -0.0 is not a
    0.0; a NaN is never)."""
    for j in range(n):
        if a[j] != b[j] or math.copysign(1.0, a[j]) != math.copysign(1.0, b[j]):
            return False
    return True


# the state of one row, stepped in place: motor and arm (load side) angle and speed, shuttle
# height and speed, whether the shuttle rides on the arm and whether the gearbox is engaged;
# then the arm angle of the last sine and cosine taken and the two (not state: a cache)
QM, WM, QL, WL, Y, V, GLUED, ENGAGED, TRIG_AT, SIN, COS = range(11)
STATE = 8


@jit
def arm_sin_cos(s: Any) -> tuple[float, float]:
    """sin and cos of the arm's angle, taken again only where it moved (the same values, to
    the bit: an arm at rest, and an angle asked for by several pieces of one step)."""
    q = s[QL]
    if q != s[TRIG_AT] or math.copysign(1.0, q) != math.copysign(1.0, s[TRIG_AT]):
        s[TRIG_AT], s[SIN], s[COS] = q, math.sin(q), math.cos(q)
    return s[SIN], s[COS]


@parallel_jit
def impact(dt: float, steps: int, p: Any, out_q: Any, out_y: Any) -> None:
    """Fill ``out_q`` (motor position) and ``out_y`` (shuttle height), (rows, steps), for the
    physics ``p`` (rows, COLUMNS). Rows are independent: they run on all cores.

    Two shortcuts give what stepping on would, to the bit: a row is integrated for its own
    ``steps`` only (a trial shorter than the longest of its run), and a state that one whole
    output step left exactly as it was (everything at rest: the arm held by friction, the
    shuttle on it or gone) stays so, each step being a function of the state alone.
    A row whose ``steps`` column is 0 is integrated to ``steps`` (the tests compare the two)."""
    for i in numba.prange(out_q.shape[0]):
        row = p[i]
        s = np.empty(COS + 1)
        before = np.empty(COS + 1)
        shortcuts = row[ROW_STEPS] > 0
        own = min(steps, int(row[ROW_STEPS])) if shortcuts else steps
        # with backlash the arm starts anywhere in the dead band: free until the gap closes;
        # a torsional spring joins them always (never one body)
        rigid = 1.0 if row[BACKLASH] == 0.0 and row[TORSION] == 0.0 else 0.0
        # (the recorded heights are above the arm's tip at rest, wherever the arm rests)
        arm0 = row[Q0] + row[BACKLASH_START] * row[BACKLASH] / 2
        lift = row[ARM] * (math.sin(arm0) - math.sin(row[Q0]))
        s[QM], s[WM], s[QL], s[WL] = row[Q0], 0.0, arm0, 0.0
        s[Y], s[V], s[GLUED], s[ENGAGED] = row[Y0] + lift, row[V0], 0.0, rigid
        s[TRIG_AT], s[SIN], s[COS] = math.nan, math.nan, math.nan
        spring = math.isfinite(row[STIFFNESS])
        k = 0
        while k < own:
            out_q[i, k] = s[QM]
            out_y[i, k] = s[Y] - lift
            k += 1
            before[:] = s
            n_sub = int(row[SUBSTEPS])
            if spring:
                # the spring's finer steps while in contact, or about to be within this step
                sin, cos = arm_sin_cos(s)
                gap = s[Y] - row[ARM] * sin
                closing = row[ARM] * cos * s[WL] - s[V]
                if gap < 2 * dt * max(closing, 0.0) + CONTACT_MARGIN_M:
                    n_sub = int(row[CONTACT_SUBSTEPS])
            h = dt / n_sub
            for _ in range(n_sub):
                if s[GLUED] and row[TORSION] > 0.0 and leaves(row, s):
                    s[GLUED] = 0.0
                drive, load, acc_y = forces(row, s, h)
                w_start = (s[WM], s[WL])
                joint_step(row, s, drive, load, h)
                # the shuttle
                if s[GLUED]:
                    v_start = s[V]
                    sin, cos = arm_sin_cos(s)
                    s[Y] = row[ARM] * sin
                    s[V] = row[ARM] * cos * s[WL]
                    # the arm can only push: where it had to pull the shuttle down (a motor
                    # running ahead in a dead band), the shuttle flies free from here
                    if row[TORSION] == 0.0:  # (on a spring: decided before the step)
                        push = row[MASS] * ((s[V] - v_start) / h + GRAVITY)
                        if push + row[RAIL] * sign(v_start) < 0.0:
                            s[GLUED], s[V] = 0.0, v_start + acc_y * h
                    continue
                s[Y] += (s[V] + 0.5 * acc_y * h) * h  # exact for the step's acceleration
                s[V] += acc_y * h
                if not spring:
                    # the motor's and the arm's mean acceleration over the step
                    acc = ((s[WM] - w_start[0]) / h, (s[WL] - w_start[1]) / h)
                    strikes(row, s, (acc_y, *acc), h)
            if shortcuts and same_bits(s, before, STATE):  # a fixed point: all later steps alike
                break
        # the steps not integrated: the state they would have shown
        out_q[i, k:] = s[QM]
        out_y[i, k:] = s[Y] - lift


@jit
def spring_torque(row: Any, q_arm: float, q_motor: float, w_arm: float, w_motor: float) -> float:
    """What a torsional spring between motor and arm exerts on the motor (the arm: minus it);
    with backlash, through its dead band (the two in series): nothing while the arm is within
    the band, the spring and its damper once a flank is reached."""
    twist, half = q_arm - q_motor, row[BACKLASH] / 2
    if half > 0.0:  # (without a band: the whole twist, the damper even at none)
        if abs(twist) <= half:
            return 0.0
        twist -= math.copysign(half, twist)
    return float(row[TORSION] * twist + row[TORSION_DAMPING] * (w_arm - w_motor))


@jit
def leaves(row: Any, s: Any) -> bool:
    """Whether an arm on a torsional spring, without the shuttle, would fall away from it
    faster than the shuttle can follow (gravity and the rail): decided before the step, so
    that the step is taken without the shuttle's inertia (after it, the separation's error
    grew with the step: first order, one per ring of the spring)."""
    arm = -spring_torque(row, s[QL], s[QM], s[WL], s[WM]) / row[ARM_INERTIA]
    sin, cos = arm_sin_cos(s)
    tip = row[ARM] * (cos * arm - sin * s[WL] * s[WL])
    return bool(tip < -GRAVITY - row[RAIL] * sign(s[V]) / row[MASS])


@jit
def forces(row: Any, s: Any, dt: float) -> tuple[float, float, float]:
    """(motor drive, load on the arm, shuttle acceleration) at the step's start."""
    m, r, weight = row[MASS], row[ARM], row[WEIGHT]
    sin, cos = arm_sin_cos(s)
    drive = drive_torque(row, s[QM], s[WM], dt)
    load, acc_y = 0.0, -GRAVITY
    if math.isfinite(row[STIFFNESS]):
        closing = r * cos * s[WL] - s[V]
        pen = r * sin - s[Y] + 0.5 * dt * closing  # at the step's midpoint
        if pen > 0.0:
            # the shuttle's weight (m g = m_s g r / r) reaches the arm through the spring only
            force = max(0.0, row[STIFFNESS] * pen + row[DAMPING] * closing)
            load = -force * r * cos
            acc_y = force / m - weight / (m * r)
    elif s[GLUED]:
        load = -weight * cos
    if s[GLUED]:
        # the shuttle rides the tip on its vertical rail (y = r sin q): its share of the inertia
        # is m r^2 cos^2 q (joint_step) and it adds m r^2 cos q sin q q'^2 (exact at any angle)
        load += m * r * r * cos * sin * s[WL] * s[WL]
    # rail friction against the shuttle's motion; a glued shuttle passes it to the arm
    rail = row[RAIL] * sign(s[V])
    if s[GLUED]:
        load -= rail * r * cos
    return drive, load, acc_y - rail / m


@jit
def joint_step(row: Any, s: Any, drive: float, load: float, dt: float) -> None:
    """Motor and arm over one step: one body while the motor pushes the arm; with backlash
    each on its own once it would pull, until the gap closes again (momentum kept); with a
    torsional spring always each on its own, joined by the spring (through the dead band)."""
    fr = (row[VISCOUS], row[COULOMB], row[STATIC])
    j_r = row[ROTOR]
    riding = row[MASS] * (row[ARM] * arm_sin_cos(s)[1]) ** 2 if s[GLUED] else 0.0
    j_load = row[ARM_INERTIA] + riding  # m_s r^2 cos^2 q while the shuttle rides the tip
    if row[TORSION] > 0.0:
        # two bodies on a spring: the motor (friction, drive, encoder) and the arm
        coupling = spring_torque(row, s[QL], s[QM], s[WL], s[WM])
        w_motor, _ = friction_step(s[WM], j_r, drive + coupling, dt, fr)
        s[WL] += (load - coupling) / j_load * dt
        # both moved at their new speeds (semi-implicit Euler: the spring's energy stays
        # bounded; moved at their mean speeds, a stiff spring's ring grew without bound)
        s[QL] += s[WL] * dt
        s[QM] += w_motor * dt
        s[WM] = w_motor
        return
    w_joint, mean_joint = friction_step(s[WM], j_r + j_load, drive + load, dt, fr)
    half = row[BACKLASH] / 2
    pull = j_load * (w_joint - s[WM]) / dt - load  # what the motor would exert on the arm
    if half == 0.0 or (s[ENGAGED] and sign(s[QL] - s[QM]) * pull <= 0.0):
        s[WM] = s[WL] = w_joint
        s[QM] += mean_joint * dt
        s[QL] = s[QM] if half == 0.0 else s[QL] + mean_joint * dt
        return
    s[ENGAGED] = 0.0
    qm0, ql0, wm0, wl0 = s[QM], s[QL], s[WM], s[WL]
    w_motor, mean_motor = friction_step(wm0, j_r, drive, dt, fr)
    w_arm = wl0 + load / j_load * dt
    s[QM] += mean_motor * dt
    s[QL] += 0.5 * (wl0 + w_arm) * dt
    s[WM], s[WL] = w_motor, w_arm
    gap = s[QL] - s[QM]
    if abs(gap) < half:
        return
    # the gap closed within the step: located (linearly), the two rejoin there if they close
    # on each other (momentum kept) and move as one for the rest of the step
    side = sign(gap)
    moved = gap - (ql0 - qm0)
    # (a gap already at the band's end, e.g. both held by friction, closes at the start)
    f = min(max((side * half - (ql0 - qm0)) / moved, 0.0), 1.0) if moved != 0.0 else 0.0
    wm_hit, wl_hit = wm0 + (w_motor - wm0) * f, wl0 + (w_arm - wl0) * f
    if (wl_hit - wm_hit) * side < 0.0:  # parting already: held at the end of the band
        s[QL] = s[QM] + side * half
        return
    qm_hit, rest = qm0 + (s[QM] - qm0) * f, (1.0 - f) * dt
    w = (j_r * wm_hit + j_load * wl_hit) / (j_r + j_load)
    w_end, mean = friction_step(w, j_r + j_load, drive + load, rest, fr)
    s[QM] = qm_hit + mean * rest
    s[QL] = s[QM] + side * half
    s[WM] = s[WL] = w_end
    s[ENGAGED] = 1.0


@jit
def strikes(row: Any, s: Any, acc: tuple[float, float, float], dt: float) -> None:
    """Collisions of the free shuttle with the arm within the step just taken (``acc``: the
    shuttle's, the motor's and the arm's acceleration over it). Each is located: the state goes
    back to it (speeds too: the arm decelerates hard under the impedance, and its speed at the
    end of the step would misstate the impact speed by a step's worth), momentum is exchanged
    there (restitution e; a rebound slower than GLUE_SPEED_M_S: the shuttle stays on the arm),
    and the rest of the step is integrated from the new velocities. A bounce may strike again
    in the same step."""
    m, r, e = row[MASS], row[ARM], row[E]
    j_a, j_r = row[ARM_INERTIA], row[ROTOR]
    acc_y, acc_m, acc_l = acc
    window = dt
    for _ in range(MAX_STRIKES):
        sin, cos = arm_sin_cos(s)
        tip_y, tip_v = r * sin, r * cos * s[WL]
        if s[GLUED] or s[Y] > tip_y or s[V] - tip_v >= 0.0:
            return
        # they met tau before the end of the step, no earlier than the strike before
        tau = min(max((tip_y - s[Y]) / max(tip_v - s[V], 1e-9), 0.0), window)
        v_c = s[V] - acc_y * tau  # the shuttle's speed when they met
        wl_c, wm_c = s[WL] - acc_l * tau, s[WM] - acc_m * tau
        ql_c = s[QL] - (s[WL] - 0.5 * acc_l * tau) * tau
        qm_c = s[QM] - (s[WM] - 0.5 * acc_m * tau) * tau
        cos = math.cos(ql_c)
        big_m = (j_a + (j_r if s[ENGAGED] else 0.0)) / (r * cos) ** 2  # struck mass at the tip
        u = v_c - r * cos * wl_c
        glued = abs(u) * e < GLUE_SPEED_M_S
        ee = 0.0 if glued else e
        v_new = v_c - (1 + ee) * big_m / (m + big_m) * u
        w_new = wl_c + (1 + ee) * m / (m + big_m) * u / (r * cos)
        j_after = j_a + (m * r * r if glued else 0.0)
        load_after = -row[WEIGHT] * cos if glued else 0.0
        if s[ENGAGED]:
            drive = drive_torque(row, qm_c, wm_c, tau)
            fr = (row[VISCOUS], row[COULOMB], row[STATIC])
            w_end, mean = friction_step(w_new, j_after + j_r, drive + load_after, tau, fr)
            s[QM], s[WM] = qm_c + mean * tau, w_end
            acc_m = (w_end - w_new) / tau if tau > 0.0 else acc_m
        else:
            # the arm on its own (a dead band, or a spring to the motor: its pull, the
            # motor's state at the step's end)
            spring = spring_torque(row, ql_c, s[QM], w_new, s[WM])
            w_end = w_new + (load_after - spring) / j_after * tau
            mean = 0.5 * (w_new + w_end)
        acc_l = (w_end - w_new) / tau if tau > 0.0 else acc_l
        s[Y] = r * math.sin(ql_c) + (v_new + 0.5 * acc_y * tau) * tau
        s[V] = r * math.cos(ql_c) * w_end if glued else v_new + acc_y * tau
        s[QL], s[WL] = ql_c + mean * tau, w_end
        s[GLUED] = 1.0 if glued else 0.0
        window = tau
