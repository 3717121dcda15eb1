"""Whether the shuttle leaves the arm after the strike, read off the load cell
(:func:`shuttle_bounces`).

The load cell sits between the shuttle and the arm's tip: while they touch it reads the
contact force (about the shuttle's weight while it rides the arm), while they are apart it
reads nothing but its noise. A shuttle that rebounds leaves the arm and strikes it again, and
the load cell shows the pause between the two strikes. The encoder's trace alone does not tell
a rebound from a ring of a compliant arm: on the zoo's development campaigns that hid a rebound
the search named it in 13 of 26 and a spring between hub and arm in its place in 12. The load
cell showed the shuttle leave the arm in every trial of all 27 such campaigns, and strike it
again in 38-100 % of them; of 135 campaigns whose answers allow no rebound it showed that in
two (a shuttle thrown off by a soft hub-arm spring, and by a backlash, in 4 of 8 and 4 of 9
trials), and the shuttle leave the arm without striking again within the recording in one more.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from transparency_ros.analysis.discrepancy.drop_trials import DropTrial, mask_runs, spread
from transparency_ros.core.config import load_drop_test

APART_SIGMAS = 5  # the load cell reads below this many sigma of its noise: the two are apart
APART_S = 0.5e-3  # for at least this long (and two samples): one low reading is noise
NOISE_S = (0.02, 0.001)  # the noise is measured over the fall this long to this long before contact
BOUNCE_TRIALS = 2  # trials that must show it (all of them where there are fewer)


@dataclass(frozen=True)
class Bounces:
    """What the load cell shows of the shuttle leaving the arm after the first strike."""

    struck_again: int  # trials where the shuttle left the arm and struck it again
    left: int  # trials where it left the arm (struck again within the recording or not)
    of: int
    pause_s: float  # the median first pause between the strikes where it struck again

    @property
    def shown(self) -> bool:
        """The recording shows the shuttle rebound: it leaves the arm and strikes it again."""
        return self.struck_again >= min(BOUNCE_TRIALS, self.of)

    @property
    def possible(self) -> bool:
        """It leaves the arm (it may come back after the recording ends)."""
        return self.left >= min(BOUNCE_TRIALS, self.of)

    def describe(self) -> str:
        return (
            f"the load cell shows the shuttle leave the arm and strike it again in "
            f"{self.struck_again} of {self.of} trials (first pause {1e3 * self.pause_s:.3g} ms)"
        )


def shuttle_bounces(trials: Sequence[DropTrial]) -> Bounces:
    """Each trial's load cell from its first contact to the end of its compared piece: where
    it reads within its noise for at least ``APART_S`` the shuttle is off the arm; where it
    then rises above the contact threshold again, the shuttle struck again."""
    threshold = load_drop_test().contact_force_threshold_n
    pauses: list[float] = []
    left = 0
    for trial in trials:
        pause = _first_pause(trial, threshold)
        if pause is None:
            continue
        left += 1
        if pause[1]:
            pauses.append(pause[0])
    return Bounces(
        struck_again=len(pauses),
        left=left,
        of=len(trials),
        pause_s=float(np.median(pauses)) if pauses else 0.0,
    )


def _first_pause(trial: DropTrial, threshold: float) -> tuple[float, bool] | None:
    """(the first pause's length, whether a strike followed it) of one trial; None where the
    load cell never reads the two apart after the first contact."""
    t, force = trial.t_h, trial.force
    fall = (t > trial.contact_s - NOISE_S[0]) & (t < trial.contact_s - NOISE_S[1])
    if np.count_nonzero(fall) < 10:
        return None  # no noise to judge by: nothing is read
    low = min(APART_SIGMAS * spread(force[fall]), threshold)
    piece = (t > trial.contact_s) & (t <= trial.end_s)
    tp, fp = t[piece], force[piece]
    for a, b in mask_runs(fp < low):
        if b - a + 1 < 2 or tp[b] - tp[a] < APART_S:
            continue
        return float(tp[b] - tp[a]), bool(np.any(fp[b + 1 :] > threshold))
    return None
