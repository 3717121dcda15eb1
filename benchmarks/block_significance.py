"""A rule tried for the robot discrepancy tool and not shipped (issue 27; issue 26 asked for
significance against the residual's own autocorrelation): a second stage after the tool's
search that names an effect where it improves the held-out balance *consistently*, however
little of the error it removes.

    .venv/bin/python benchmarks/block_significance.py survey ZOO_DIR --t 5 [--log LOG.jsonl.gz]
    .venv/bin/python benchmarks/block_significance.py survey ZOO_DIR --t inf --first FIRST.jsonl
    .venv/bin/python benchmarks/block_significance.py first FIRST.jsonl ZOO_DIR
    .venv/bin/python benchmarks/block_significance.py pendubot DIR [DIR ...] --t 5

The statistic: the held-out squared error (in noise floors) the step removes, summed over blocks
of ``BLOCK`` compared points (62: about 1 s) of each held-out run and joint; per joint the
blocks' mean over its standard error (t). A candidate of the second stage passes where some
joint it acts on (``RobotProblem.sensor_scope``) has t >= T and none has t < -``WORSE``, with
the tool's other conditions (meaningful, interval without its null value, the information
criterion better by 10, a tenth of a floor); the best t is named, all refitted, again until
none passes. The tool's own search (the share rule) runs first, unchanged.

``survey`` runs benchmarks/robot_zoo.py's survey with the second stage; with ``--first`` it also
writes every candidate of the second stage's first round (its t per joint) as JSON lines, and
``--t inf`` names nothing in it: ``first`` then tabulates, per threshold, the robots where a
candidate outside the answers would pass and the required effects that would. ``pendubot``
runs the tool with the second stage on directories of CSV runs of the real pendubot (e.g.
those benchmarks/concealed_robot.py writes) and prints what it names.

Results (twelfth session) are in docs/robots.md, part 5.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import sys
import weakref
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
sys.path.insert(0, str(ROOT))
from robot_zoo import TWINS  # noqa: E402 - the zoo's twins: the balance's one delay

BLOCK = 62  # compared points per block (16 ms apart: about 1 s)
WORSE = 2.0  # no joint's t below -WORSE
_IDS: weakref.WeakKeyDictionary[Any, np.ndarray] = weakref.WeakKeyDictionary()


def _block_ids(problem: Any) -> np.ndarray:
    """Per held-out element (run, sample, joint as the error orders them), its block (made
    once per problem: every candidate of every round is judged on the same blocks)."""
    if problem not in _IDS:
        _IDS[problem] = _made_ids(problem)
    return _IDS[problem]


def _made_ids(problem: Any) -> np.ndarray:
    dof = problem.model.dof
    out = []
    for k, run in enumerate(problem.held_runs):
        n = run.t.size
        sample = np.repeat(np.arange(n), dof)
        joint = np.tile(np.arange(dof), n)
        out.append((k * dof + joint) * 1_000_000 + sample // BLOCK)
    return np.concatenate(out)


def joint_t(problem: Any, step: Any, base: Any) -> list[float]:
    """Per joint ``step`` acts on, the t of its blocks' reduction of the squared error."""
    ids = _block_ids(problem)
    scope = problem.sensor_scope(step.added, False)
    mask = np.ones(ids.size, dtype=bool) if scope is None else scope[0]
    gained = base.err[mask] ** 2 - step.err[mask] ** 2
    sub = ids[mask]
    joint = (sub // 1_000_000) % problem.model.dof
    out = []
    for j in np.unique(joint):
        sel = joint == j
        _, index = np.unique(sub[sel], return_inverse=True)
        sums = np.bincount(index, gained[sel])
        spread = sums.std(ddof=1) if sums.size >= 3 else 0.0
        out.append(float(sums.mean() / (spread / math.sqrt(sums.size))) if spread > 0 else 0.0)
    return out


def second_stage(threshold: float, first: Path | None, robot: list[str]) -> type:
    """The tool's loop with the second stage after its search (``threshold``: T)."""
    from transparency_ros.analysis.discrepancy import discover as d  # noqa: PLC0415
    from transparency_ros.analysis.discrepancy.findings import update_findings  # noqa: PLC0415
    from transparency_ros.analysis.discrepancy.fitting import aic, interval, rmse  # noqa: PLC0415
    from transparency_ros.analysis.discrepancy.steps import (  # noqa: PLC0415
        Base,
        not_named,
        null_inside,
        total,
    )

    class SecondStage(d.Discoverer):
        def _checked_last(self, report, effects, params, held_err, *, remaining, floor):  # type: ignore[no-untyped-def]
            effects, params, held_err = super()._checked_last(
                report, effects, params, held_err, remaining=remaining, floor=floor
            )
            problem = self.problem
            left = [
                c
                for c in not_named(list(problem.candidates()), effects)
                if not (getattr(c, "declared", False) or getattr(c, "checked_last", False))
            ]
            first_round = True
            while left:
                err = held_err
                base = Base(err, rmse(err), aic(err, total(params)), floor, effects, params)
                passing = []
                for cand in left:
                    s = self._single(effects, params, cand, base)
                    if not (s.meaningful and not null_inside(s) and s.aic < base.aic - 10
                            and s.judged[0] - s.judged[1] >= 0.1 * s.judged[2]):  # fmt: skip
                        continue
                    ts = joint_t(problem, s, base)
                    if first is not None and first_round:
                        with first.open("a") as f:
                            f.write(json.dumps({"robot": robot[0], "cand": cand.name, "t": ts,
                                                "share": float(s.gain)}) + "\n")  # fmt: skip
                    if max(ts) >= threshold and min(ts) >= -WORSE:
                        passing.append((max(ts), s))
                first_round = False
                if not passing:
                    break
                t, step = max(passing, key=lambda x: x[0])
                cand = step.added[0]
                found = self._finding(cand, step, base, base.rmse, step.rmse)
                note = f"{found.evidence}; consistent in held-out blocks (t {t:.1f})"
                report.findings.append(dataclasses.replace(found, evidence=note))
                effects = [*effects, cand]
                params, held_err = step.params, step.err
                if step.joint:
                    update_findings(report, effects, params, interval(step.result, step.result.x))
                left = not_named(left, effects)
            return effects, params, held_err

    return SecondStage


def _survey(args: argparse.Namespace) -> int:
    import robot_zoo  # noqa: PLC0415

    from transparency_ros.analysis.discrepancy import discover  # noqa: PLC0415

    robot = [""]
    first = Path(args.first) if args.first else None
    discover.Discoverer = second_stage(args.t, first, robot)  # type: ignore[misc]
    run_tool = robot_zoo.run_tool

    def named_run(directory: Path, *a: Any, **k: Any) -> dict[str, Any]:
        robot[0] = directory.name
        return run_tool(directory, *a, **k)

    robot_zoo.run_tool = named_run  # (the pool's workers are forked after this)
    log = Path(args.log) if args.log else None
    rows = robot_zoo.survey(Path(args.directory), None, args.jobs, log)
    robot_zoo.report(rows, " ".join(["benchmarks/block_significance.py", *sys.argv[1:]]), None)
    return 0


def _first(args: argparse.Namespace) -> int:
    rows = [json.loads(line) for line in Path(args.log).read_text().splitlines()]
    labelled = []
    for row in rows:
        truth = yaml.safe_load((Path(args.directory) / row["robot"] / "answers.yaml").read_text())
        c = row["cand"]
        required = c in truth["required"] or TWINS.get(c) in truth["required"]
        label = "required" if required else "allowed" if c in truth["allowed"] else "outside"
        labelled.append((row["robot"], c, label, max(row["t"]), min(row["t"])))
    print(f"{len(labelled)} candidates of the second stage's first round, "
          f"{len({r[0] for r in labelled})} robots")  # fmt: skip
    print("| T | robots where one outside the answers passes | required effects that pass |")
    print("|---|---|---|")
    for t in (3, 4, 5, 6, 8, 10, 12):
        outside = {
            r for r, _, lab, hi, lo in labelled if lab == "outside" and hi >= t and lo >= -WORSE
        }
        right = [
            (r, c)
            for r, c, lab, hi, lo in labelled
            if lab == "required" and hi >= t and lo >= -WORSE
        ]
        print(f"| {t} | {len(outside)} | {len(right)} |")
    by_label: dict[str, list[float]] = defaultdict(list)
    for _, _, lab, hi, lo in labelled:
        if lo >= -WORSE:
            by_label[lab].append(hi)
    for lab, values in sorted(by_label.items()):
        print(f"{lab}: largest t {max(values):.1f} of {len(values)}")
    return 0


def _pendubot(args: argparse.Namespace) -> int:
    from transparency_ros.analysis.discrepancy.robot import RobotProblem, robot_result  # noqa: PLC0415
    from transparency_ros.analysis.robot_data import Columns, read_joint_csv  # noqa: PLC0415
    from transparency_ros.core.robot_model import RobotModel  # noqa: PLC0415

    urdf = ROOT.parent / "shared" / "external" / "double_pendulum" / "pendubot.urdf"
    model = RobotModel.from_urdf(urdf)
    columns = Columns.parse("time=time,position=pos_meas{},velocity=vel_meas{},torque=tau_con{}")
    loop = second_stage(args.t, None, [""])
    for directory in args.directories:
        files = sorted(Path(directory).glob("*.csv*"))
        recs = [read_joint_csv(str(f), list(model.joint_names), columns) for f in files]
        problem = RobotProblem(model, recs)
        result = robot_result(problem, loop(problem).run())
        named = [(f["effect"], f["joint"], {k: round(v, 4) for k, v in f["parameters"].items()})
                 for f in result["findings"]]  # fmt: skip
        print(f"{Path(directory).name}: {named}", flush=True)
    return 0


def main() -> int:
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")  # (no ROS is started)
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    s = sub.add_parser("survey", help="robot_zoo.py's survey with the second stage")
    s.add_argument("directory")
    s.add_argument("--t", type=float, required=True, help="the threshold T (inf: none)")
    s.add_argument("--jobs", type=int, default=2)
    s.add_argument("--log", default=None, help="robot_zoo's JSON lines (gzip)")
    s.add_argument("--first", default=None, help="the first round's candidates (JSON lines)")
    f = sub.add_parser("first", help="tabulate a --first file against the zoo's answers")
    f.add_argument("log")
    f.add_argument("directory")
    p = sub.add_parser("pendubot", help="the tool with the second stage on real pendubot runs")
    p.add_argument("directories", nargs="+")
    p.add_argument("--t", type=float, required=True)
    args = parser.parse_args()
    return {"survey": _survey, "first": _first, "pendubot": _pendubot}[args.command](args)


if __name__ == "__main__":
    raise SystemExit(main())
