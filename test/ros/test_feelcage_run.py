"""Table 2 cells through the real node processes, checked against the core engine.

Each cell starts actuator_driver (simulated actuator striking the ball), contact_estimator and
feel_cage_behavior as their own processes; about 10 s per cell.
"""

from __future__ import annotations

import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pytest

pytest.importorskip("rclpy")

from transparency_ros.analysis import feelcage_sim as sim
from transparency_ros.core import feel_cage as fc
from transparency_ros.core import strict_json
from transparency_ros.core.config import get_actuator
from transparency_ros.ros.feelcage_run import CellRun

pytestmark = pytest.mark.ros

# The core engine is evaluated at the nodes' measured latency (onset sample -> act torque on the
# motor), from two samples of the 1 kHz loop before it to 10 ms after: the act phase itself runs
# late on a loaded machine (beside one CPU hog the cage was seen 9 ms later than the core's at
# the measured latency: the driver's loop, stalled, samples the arm past the cage late). Alone,
# the cage came within 0.7-1.6 ms of the core's at the measured latency (5 trials).
LATENCY_EARLY_S, LATENCY_LATE_S = 0.002, 0.010

# run_cell in its own process, as `transparency feelcage` runs it: a process that has created
# many rclpy contexts (this test session) can miss service responses (README, Known issues)
_SCRIPT = """
import dataclasses, json, sys
from transparency_ros.core.feel_cage_config import load_setup
from transparency_ros.ros.feelcage_run import run_cell
params_file = sys.argv[3] if len(sys.argv) > 3 else None
run = run_cell(sys.argv[1], sys.argv[2], load_setup(), settle_s=3.0, params_file=params_file)
print(json.dumps(dataclasses.asdict(run)))
"""


def _run_cell_in_a_fresh_process(actuator: str, ball: str, *params_file: str) -> CellRun:
    done = subprocess.run(
        [sys.executable, "-c", _SCRIPT, actuator, ball, *params_file],
        capture_output=True, text=True, timeout=180, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-2000:]
    data = strict_json.loads(done.stdout.strip().splitlines()[-1])
    record = data.pop("record")
    record["outcome"] = fc.Outcome(record["outcome"])
    return CellRun(record=fc.TrialRecord(**record), **data)


@pytest.mark.parametrize(
    ("actuator", "ball", "outcome"),
    [
        ("EC60", "bocce", fc.Outcome.FEEL_AND_CAGE),
        ("EC60", "rubber", fc.Outcome.FEEL),
        ("T2822", "lacrosse", fc.Outcome.NO_DETECTION),
    ],
)
def test_cell_through_the_nodes_matches_the_paper_and_the_core(
    actuator: str, ball: str, outcome: fc.Outcome
) -> None:
    """The paper's cell in the core engine; through the three node processes in real time, the
    outcome the core engine gives at the latency the nodes actually had, from the sample that
    crossed the threshold to the act torque on the motor (t_process plus the command's trip).
    With the paper's 1 ms the core cages EC60/bocce up to about 28 ms of it; four Python
    processes on a busy 2-core machine sometimes take longer, and the ball is then only felt,
    as the core predicts for that latency. Whether the chain keeps its deadlines is a speed goal
    (docs/feel_cage.md, `transparency feelcage`), not this test's."""
    setup = sim.load_setup()
    sweep = sim.steady_sweep(get_actuator(actuator), setup)
    core = sim.simulate_cell(actuator, ball, setup, sweep)
    assert core.outcome is outcome  # the paper's cell (Table 2)

    run = _run_cell_in_a_fresh_process(actuator, ball)
    record = run.record
    # e_s measured from /estimated_effort agrees with the core's to a fraction of epsilon
    e_s = sweep.steady_error_rad
    assert run.steady_error_rad == pytest.approx(e_s, abs=setup.epsilon_rad / 2), run
    assert record.t_budget_s is not None, run  # the simulator saw the strike and the ball leave
    if outcome is fc.Outcome.NO_DETECTION:
        assert record.outcome is outcome, (run, core)
        assert record.t_feel_s is None
        return
    # detected after the true contact, and within a few samples of the core's detection, plus
    # whatever the driver's loop went without a sample between contact and detection beyond its
    # 1 ms period (under a loaded suite it was seen at 18.7 ms against the core's 7.9)
    assert record.t_feel_s is not None and core.t_feel_s is not None, (record, core)
    # (a detection before the contact is a false one: under two suites at once it came 78 ms
    # early, docs/known_issues.md; sample_gap_s then says how the driver's samples went)
    assert record.t_feel_s > 0.0, ("detected before the contact", record, run.sample_gap_s)
    assert run.sample_gap_s is not None, run
    stalled = max(0.0, run.sample_gap_s - 0.001)
    assert record.t_feel_s < core.t_feel_s + 0.005 + stalled, (record, core, run)
    assert record.t_process_s is not None and record.t_process_s >= setup.process_time_s
    # the core at the nodes' own latency gives the same outcome
    latency = run.t_torque_s if run.t_torque_s is not None else record.t_process_s
    at = {
        t: sim.simulate_cell(actuator, ball, replace(setup, process_time_s=t), sweep).outcome
        for t in (max(0.0, latency - LATENCY_EARLY_S), latency, latency + LATENCY_LATE_S)
    }
    assert record.outcome in at.values(), (record, run.t_torque_s, at)
    if record.outcome is fc.Outcome.FEEL_AND_CAGE:
        assert run.t_torque_s is not None, record  # caged by the act torque
        assert record.t_total_s is not None and record.t_total_s < record.t_budget_s


def test_the_shipped_parameter_file_runs_the_nodes_by_hand() -> None:
    """config/feel_cage_nodes.yaml, as docs/feel_cage.md starts the three nodes with it
    (--params-file): U10DD's sweep error is the core's (the driver's actuator, gains and rate and
    the estimator's k_s took effect) and the ball is felt. (Whether the cage then closes in
    time depends on the host's pace through ROS: docs/feel_cage.md.)"""
    root = Path(__file__).resolve().parents[2]
    run = _run_cell_in_a_fresh_process("U10DD", "rubber", str(root / "config" /
                                                              "feel_cage_nodes.yaml"))  # fmt: skip
    setup = sim.load_setup()
    sweep = sim.steady_sweep(get_actuator("U10DD"), setup)
    e_s = sweep.steady_error_rad
    assert run.steady_error_rad == pytest.approx(e_s, abs=setup.epsilon_rad / 2), run
    assert run.record.outcome in (fc.Outcome.FEEL, fc.Outcome.FEEL_AND_CAGE), run
