"""What a drive's own recorded torque shows of its limit (:func:`drive_clip`).

The bag contract's ``/joint_states`` effort is the drive's torque. A drive that clips its
torque (a current limit) shows it there: the recorded torque stays at one level while the
impedance law, k_s (theta_d - theta) from the recorded angle, asks for more. That level is read
off the recording, not fitted: on the zoo's campaigns with a clipped drive the clip acted late
in each trial, where the encoder's trace changed too little for any fit to name it (4 of 12
missed on fresh seeds 9500-9599), while the recorded torque stood at the limit within its
resolution.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from transparency_ros.analysis.discrepancy.drop_trials import DropTrial, at_rest, mask_runs, spread
from transparency_ros.analysis.discrepancy.model import FloatArray

CLIP_SHARE = 0.1  # a clipped reading is at least this share of the asked torque below it
CLIP_RUN = 3  # consecutive clipped readings (one glitch is no limit)
CLIP_FLAT = 0.05  # a limit holds one level: its readings within this share of their median
CLIP_TRIALS = 2  # trials that must show it (all of them where fewer have efforts)
NOISE_SIGMAS = 5  # readings off the impedance law by more than this many sigma at rest


@dataclass(frozen=True)
class DriveClip:
    """The level the drive's recorded torque is clipped at."""

    limit_nm: float
    interval_nm: tuple[float, float]  # the clipped readings' range and their noise
    asked_nm: float  # the largest torque the impedance law asked for where it was clipped
    trials: int  # trials that show it
    of: int  # trials with recorded torques

    def describe(self) -> str:
        return (
            f"the recorded drive torque held at {self.limit_nm:.4g} N m while the impedance "
            f"law asked up to {self.asked_nm:.3g} N m, in {self.trials} of {self.of} trials"
        )


def drive_clip(trials: Sequence[DropTrial]) -> DriveClip | None:
    """The level the recorded drive torque is held at while the impedance law asks for more,
    in at least ``CLIP_TRIALS`` trials (all of them where fewer recorded torques); None where
    no trial recorded torques or they follow the law."""
    recorded = [(t, t.effort) for t in trials if t.effort is not None]
    shown = [c for c in (_clipped(t, effort) for t, effort in recorded) if c is not None]
    if not recorded or len(shown) < min(CLIP_TRIALS, len(recorded)):
        return None
    levels = np.concatenate([c[0] for c in shown])
    noise = max([c[1] for c in shown] + [1e-6])
    return DriveClip(
        limit_nm=float(np.median([np.median(c[0]) for c in shown])),
        interval_nm=(float(levels.min() - 2 * noise), float(levels.max() + 2 * noise)),
        asked_nm=max(c[2] for c in shown),
        trials=len(shown),
        of=len(recorded),
    )


def _clipped(trial: DropTrial, effort: FloatArray) -> tuple[FloatArray, float, float] | None:
    """(the clipped readings' magnitudes, the torque's noise at rest, the largest torque asked
    there) of one trial and its recorded torque; None where it follows the impedance law."""
    asked = trial.k_s * (trial.theta_d - trial.q)
    ok = np.isfinite(effort)
    rest = ok & at_rest(trial.t_q, trial.contact_s)
    noise = spread(effort[rest] - asked[rest])
    steps = np.abs(np.diff(trial.q))
    count = float(steps[steps > 0].min()) if np.any(steps > 0) else 0.0
    # what the angle's counts and the torque's noise allow between the two
    tolerance = trial.k_s * count + NOISE_SIGMAS * noise
    short = np.abs(asked) - np.abs(effort)
    clip = (
        ok
        & (np.sign(effort) == np.sign(asked))
        & (short > np.maximum(CLIP_SHARE * np.abs(asked), tolerance))
    )
    runs = _runs(clip, CLIP_RUN)
    if not runs.any():
        return None
    levels = np.abs(effort[runs])
    median = float(np.median(levels))
    if median <= 0 or float(levels.max() - levels.min()) > CLIP_FLAT * median:
        return None
    return levels, noise, float(np.abs(asked[runs]).max())


def _runs(mask: npt.NDArray[np.bool_], length: int) -> npt.NDArray[np.bool_]:
    """``mask`` where it holds for at least ``length`` consecutive samples."""
    out = np.zeros(mask.size, dtype=bool)
    for first, last in mask_runs(mask):
        if last - first + 1 >= length:
            out[first : last + 1] = True
    return out
