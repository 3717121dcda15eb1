"""What would tell apart two explanations of a drop test that fit its recordings alike, where the
recordings say why they cannot (DropProblem.told_apart, findings.alike_fits)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from transparency_ros.analysis.discrepancy.drop_effects import (
    DropEffect,
    DropRestitution,
    HubArmCompliance,
)

if TYPE_CHECKING:
    from transparency_ros.analysis.discrepancy.drop import DropProblem

# an arm whose inertia is under this share of the shuttle's m r^2 at its tip is light against
# it (told_apart: a rebound and a hub spring then act alike on the motor; the zoo's arms are
# 0.01-0.04 of it)
LIGHT_ARM = 0.25


def told_apart(
    problem: DropProblem, named: Sequence[DropEffect], other: Sequence[DropEffect]
) -> str:
    """What would tell ``named`` from ``other``, which explained the held-out recordings
    alike, where the recordings say why they cannot ("" where they do not):

    * a constant torque (an offset) and a change of the Coulomb torque (a drift of it
      alone) act alike on an arm that turns one way, which every trial's arm did after
      contact (on the zoo the two fit to eight digits alike there: zoo_12791,
      docs/discrepancy.md);
    * a contact that rebounds and a spring between hub and arm act alike on the motor
      where the arm is light against the shuttle (its inertia under a quarter of the
      shuttle's m r^2 at the tip): the same series spring, at the tip or at the hub
      (ShownRestitution)."""
    if not len(named) == len(other) == 1:
        return ""
    kinds = {_alike_kind(e) for e in (*named, *other)}
    n = len(problem.fit_trials) + len(problem.held_trials)
    if kinds == {"constant", "coulomb"} and not turned_back(problem):
        return (
            f"the arm turned one way after contact in all {n} trials, against which a "
            "Coulomb torque is a constant torque: a trial in which it turns back (a drop "
            "that rebounds, or the drive moving it both ways) tells them apart"
        )
    if kinds != {"rebound", "hub spring"}:
        return ""
    trials = (*problem.fit_trials, *problem.held_trials)
    share = float(np.mean([t.arm_inertia_kgm2 / (t.mass_kg * t.arm_m**2) for t in trials]))
    if share < LIGHT_ARM:
        return (
            f"the arm is light against the shuttle (its inertia {share:.2g} of the "
            "shuttle's m r^2 at the tip), so a contact that rebounds and a spring between "
            "hub and arm act alike on the motor, one spring in series at the tip or at the "
            "hub: a tap on the arm with the hub clamped tells them apart (a spring rings "
            "at its frequency, a contact does not)"
        )
    return ""


def turned_back(problem: DropProblem) -> int:
    """The trials whose arm turned back after contact: came back from the farthest it
    had turned (the strike turns it to negative theta, as analysed) by more than two
    counts of the encoder or three times its noise at rest. (Not the phases' reversals:
    the speed of an arm creeping count by count changes sign in its readings' noise.)"""
    least = max(2 * problem.encoder_count, 3 * problem.encoder_noise_rad)
    turned = 0
    for t in (*problem.fit_trials, *problem.held_trials):
        q = t.q[t.t_q > t.contact_s]
        turned += bool(q.size and float(np.max(q - np.minimum.accumulate(q))) > least)
    return turned


def _alike_kind(effect: DropEffect) -> str:
    """What ``told_apart`` knows an effect as: 'constant' (an offset), 'coulomb' (a drift of
    the Coulomb torque alone), 'rebound', 'hub spring' or ''."""
    if effect.name == "torque_offset":
        return "constant"
    if getattr(effect, "free", None) == (False, False, True):
        return "coulomb"
    if isinstance(effect, DropRestitution):
        return "rebound"
    if isinstance(effect, HubArmCompliance):
        return "hub spring"
    return ""
