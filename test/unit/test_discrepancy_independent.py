"""The discrepancy tool on a drop-test rig written from scratch (benchmarks/independent_rig.py:
its own integrator, Hunt-Crossley contact, Stribeck friction, exact geometry, bags written with
rosbags), sharing no code with the tool. The survey over 30 campaigns is a benchmark; this checks
one campaign that has most of what rigs elsewhere do differently at once."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import Any

import pytest

from transparency_ros.analysis.discrepancy.discover import Discoverer
from transparency_ros.analysis.discrepancy.drop import (
    DropProblem,
    load_drop_nominal,
    load_drop_trial,
)
from transparency_ros.analysis.discrepancy.drop_bounce import shuttle_bounces
from transparency_ros.bag.reader import find_bags

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
import independent_rig


def test_a_rig_that_is_not_ours_nothing_hidden_only_the_weight_is_named(tmp_path: Path) -> None:
    """Seed 302: a U10GB whose strike turns the arm to positive theta (declared), recorded from
    0.2 s before contact without the release, no /joint_commands, theta_d 0.28 rad from
    horizontal. Before this rig existed the tool left 0.2 rad unexplained here (heights were
    taken above a horizontal arm's tip); the weight resting on the arm is all there is."""
    out = independent_rig.write_campaign(tmp_path / "c", 302)
    labels = json.loads((out / "labels.json").read_text())
    conventions = labels["conventions"]
    assert labels["hidden"] == {} and labels["weight_on_arm"]
    assert conventions["strike_sign"] == 1 and conventions["declares_sign"]
    assert conventions["triggered_s"] is not None and not conventions["commands"]
    trials = [load_drop_trial(b) for b in find_bags([str(out / "bags")])]
    problem = DropProblem(trials, load_drop_nominal(None, trials))
    assert problem.notes[0] == "strike direction: positive theta in 6 of 6 trials (see below)"
    # the drops that take longer than the 0.2 s recorded before contact have no release
    falls = [math.sqrt(2 * h / 9.80665) for h in independent_rig.HEIGHTS]
    unrecorded = sum(fall > conventions["triggered_s"] for fall in falls)
    assert unrecorded >= 2
    assert sum(not t.release_recorded for t in trials) == unrecorded
    report = Discoverer(problem).run()
    assert _beside_a_shown_chatter(report, trials) == ["payload_gravity"]
    weight = labels_weight(trials)
    assert report.findings[0].parameters["mgl_nm"] == pytest.approx(weight, rel=0.15)
    assert report.final_heldout_rmse < 0.05 * report.heldout_rmse_nominal


def _beside_a_shown_chatter(report: Any, trials: list[Any]) -> list[str]:
    """The findings' effects but a rebound, which may be named only where the load cell shows
    the shuttle strike the arm again and only as small as this rig's contact makes it: its
    Hunt-Crossley damping (alpha 2-4 s/m) is nearly inelastic at the highest drops, not at the
    lowest, and the shuttle chatters on a heavy arm (pauses of 1.5-6 ms between strikes in 6
    of 6 trials of seed 301, 4 of 6 of seed 302). The labels hide no rebound."""
    for finding in report.findings:
        if finding.effect == "restitution":
            assert shuttle_bounces(trials).shown
            assert finding.parameters["coefficient"] < 0.1
    return [f.effect for f in report.findings if f.effect != "restitution"]


def labels_weight(trials: list) -> float:  # type: ignore[type-arg]
    """m_s g r of the bags' own custom_data, what the weight on the arm should come out as."""
    t = trials[0]
    return float(t.mass_kg * 9.81 * t.arm_m)


@pytest.mark.parametrize("seed", [303, 301])
def test_a_coarse_encoder_on_a_rig_that_is_not_ours_is_named_with_its_step(
    tmp_path: Path, seed: int
) -> None:
    """Seed 303: a U10DD with a 2048-count encoder. Its fall is braked by the rig's own rail
    (0.03 % of g, below what may be local gravity): compared with the tool's g, that left
    0.8 mrad in a fall, and the quantization, which explains the encoder's error almost
    entirely (0.91 -> 0.06 mrad), removed too little of the whole to be named.
    Seed 301: a U10GB with a 2048-count encoder and a soft impedance (k_s 2 N m/rad against
    0.25-0.28 N m of friction with a Stribeck hump): the heights keep 0.29 mrad of the arm's
    settling that the tool's Coulomb friction misses and the 3 mrad lattice hides from the
    encoder. The lattice explains the encoder's error (1.0 -> 0.15 mrad) but only 66 % of the
    whole: it is judged on the encoder, the only sensor it acts on."""
    out = independent_rig.write_campaign(tmp_path / "c", seed)
    labels = json.loads((out / "labels.json").read_text())
    step = labels["hidden"]["quantization"]["step_rad"]
    trials = [load_drop_trial(b) for b in find_bags([str(out / "bags")])]
    report = Discoverer(DropProblem(trials, load_drop_nominal(None, trials))).run()
    assert _beside_a_shown_chatter(report, trials) == ["payload_gravity", "quantization"]
    found = {f.effect: f for f in report.findings}
    assert found["quantization"].parameters["step_rad"] == pytest.approx(step, rel=0.01)
