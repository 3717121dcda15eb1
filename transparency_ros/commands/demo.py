"""``transparency demo``: run everything the package can show so far and list what it made.

``make demo`` calls this. It runs on the simulated side only (no hardware), writes into
``--out`` and prints one line per artefact, so a new user sees at a glance what exists.
"""

from __future__ import annotations

import argparse
import shutil
import time
from pathlib import Path
from typing import Any

from transparency_ros.analysis.fig2 import model_curves, plot_fig2
from transparency_ros.commands.model import curves_report, model_summary
from transparency_ros.commands.rig import parse_heights
from transparency_ros.core import strict_json
from transparency_ros.core.config import load_actuators, load_drop_test
from transparency_ros.core.contact_model import ContactModel


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "demo",
        help="run the demonstration (what `make demo` does) and list what it produced",
        description="Reproduce what the package can reproduce so far, without hardware, and "
        "write the results into OUT.",
    )
    p.add_argument(
        "--out",
        default="demo_output",
        metavar="DIR",
        help="output directory (default: demo_output)",
    )
    p.add_argument(
        "--no-ros", action="store_true", help="skip the steps that start ROS nodes (model only)"
    )
    p.add_argument(
        "--heights",
        default="0.03,0.05,0.1,0.2,0.4,0.7,1.1",
        metavar="M,M,...",
        help="drop heights of the rig step (default: the paper's range, 7 heights)",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    actuators = load_actuators()
    drop_test = load_drop_test()
    models = [ContactModel.from_config(a, drop_test) for a in actuators.values()]

    print("transparency demo: contact model of the paper (eq. 2-4), Table 1 actuators")
    curves = model_curves(models)
    png = plot_fig2(curves, out / "fig2_model.png")
    data = out / "fig2_model.json"
    data.write_text(strict_json.dumps({"curves": curves_report(curves)}, None), encoding="utf-8")
    summary = out / "actuators_summary.json"
    summary.write_text(strict_json.dumps([model_summary(m) for m in models]), encoding="utf-8")

    print(f"  {'actuator':<8} {'regime':<12} {'min. detectable T [J]':>22} {'t_r at 1 J [ms]':>16}")
    for c in curves:
        at = c.model.solve([1.0])
        t_r = "not detected" if not at.detected[0] else f"{at.t_r_s[0] * 1e3:.2f}"
        print(
            f"  {c.model.actuator:<8} {c.model.regime.value:<12} "
            f"{c.min_detectable_energy_j:>22.4g} {t_r:>16}"
        )
    produced = [
        (png, "Fig. 2a/2b model curves (t_r and energy loss vs collision energy)"),
        (data, "the curves as JSON"),
        (summary, "per-actuator model constants and minimum detectable energy"),
    ]
    if not args.no_ros:
        produced += _driver_step(out)
        produced += _rig_step(out, parse_heights(args.heights))
    print("produced:")
    for path, what in produced:
        print(f"  {path}  {what}")
    print(f"done in {time.perf_counter() - started:.1f} s")
    return 0


def _driver_step(out: Path) -> list[tuple[Path, str]]:
    """The actuator_driver node with a simulated U10DD (MIT mode) answering a step command."""
    # ROS is imported here only: the model part of the demo runs without it.
    from transparency_ros.ros.demo_driver import plot_step, run_driver_demo  # noqa: PLC0415

    print("\ntransparency demo: actuator_driver node, simulated U10DD over MIT mode (virtual CAN)")
    result = run_driver_demo(protocol="mit", actuator="U10DD", target_rad=1.0)
    csv = out / "driver_step.csv"
    lines = ["t_s,position_rad,velocity_rad_s,effort_nm"]
    lines += [f"{t:.6f},{p:.6f},{v:.6f},{e:.6f}" for t, p, v, e in result.samples]
    csv.write_text("\n".join(lines) + "\n", encoding="utf-8")
    png = plot_step(
        result,
        out / "driver_step.png",
        "actuator_driver: step to 1 rad, k_s = 2 N·m/rad, simulated U10DD",
    )
    dead_band = load_actuators()["U10DD"].coulomb_friction_nm / 2.0  # k_s = 2 N m/rad
    print(
        f"  /joint_states at {result.rate_hz:.0f} Hz; position {result.final_position_rad:.3f} rad "
        f"for a 1.000 rad command (Coulomb friction / k_s = {dead_band:.3f} rad)"
    )
    state = "disabled" if result.motor_disabled_at_exit else "STILL ENABLED"
    print(f"  after SIGINT the simulated motor was {state}")
    if not result.motor_disabled_at_exit:
        raise RuntimeError("the driver left the simulated motor enabled:\n" + result.log_tail)
    return [
        (png, "actuator_driver step response (position and drive torque)"),
        (csv, "the /joint_states samples of that step"),
    ]


def _rig_step(out: Path, heights: list[float]) -> list[tuple[Path, str]]:
    """Drop trials through the nodes for the four actuators, recorded and evaluated (Fig. 2)."""
    from transparency_ros.analysis.drop_eval import evaluate, summarise  # noqa: PLC0415
    from transparency_ros.core.contact_model import model_for  # noqa: PLC0415
    from transparency_ros.ros.rig_run import run_rig  # noqa: PLC0415

    print(
        f"\ntransparency demo: drop-test rig through the nodes, 4 actuators x {len(heights)} "
        "heights, one MCAP bag per trial"
    )
    bags = out / "rig_bags"
    if bags.exists():
        shutil.rmtree(bags)  # a fresh campaign (bags are never overwritten)
    for actuator in ("U10DD", "EC60", "T2822", "U10GB"):
        recorded = run_rig(actuator, heights, bags)
        print(f"  {actuator}: {len(recorded)} bags")
    results = evaluate([bags])
    summary = summarise(results)
    curves = model_curves([model_for(s.actuator) for s in summary])
    png = plot_fig2(
        curves,
        out / "fig2_measured.png",
        title=f"Fig. 2 from {len(results)} drop-test bags (points) against the model (lines)",
        measured=results,
    )
    data = out / "fig2_measured.json"
    data.write_text(
        strict_json.dumps(
            {"trials": [r.as_dict() for r in results], "summary": [vars(s) for s in summary]}
        ),
        encoding="utf-8",
    )
    for s in summary:
        slope = "-" if s.delta_e_slope is None else f"{s.delta_e_slope:.2f}"
        print(
            f"  {s.actuator}: detected {s.detected}/{s.trials}; dE/T slope {slope} "
            f"(model {s.model_delta_e_slope:.2f})"
        )
    return [
        (bags, "the drop trials as rosbag2 MCAP bags (transparency eval reads them)"),
        (png, "Fig. 2a/2b measured from the bags against the model"),
        (data, "per-trial t_t, T, t_r, v_s,e, dE, F_mu, F_est and the per-actuator summary"),
    ]
