"""``transparency demo``: run everything the package can show so far and list what it made.

``make demo`` calls this. It runs on the simulated side only (no hardware), writes into
``--out`` and prints one line per artefact, so a new user sees at a glance what exists.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

from transparency_ros.analysis.fig2 import model_curves, plot_fig2
from transparency_ros.commands.model import curves_report, model_summary
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
    data.write_text(json.dumps({"curves": curves_report(curves)}), encoding="utf-8")
    summary = out / "actuators_summary.json"
    summary.write_text(json.dumps([model_summary(m) for m in models], indent=2), encoding="utf-8")

    print(f"  {'actuator':<8} {'regime':<12} {'min. detectable T [J]':>22} {'t_r at 1 J [ms]':>16}")
    for c in curves:
        at = c.model.solve([1.0])
        t_r = "not detected" if not at.detected[0] else f"{at.t_r_s[0] * 1e3:.2f}"
        print(
            f"  {c.model.actuator:<8} {c.model.regime.value:<12} "
            f"{c.min_detectable_energy_j:>22.4g} {t_r:>16}"
        )
    print("produced:")
    print(f"  {png}  Fig. 2a/2b model curves (t_r and energy loss vs collision energy)")
    print(f"  {data}  the curves as JSON")
    print(f"  {summary}  per-actuator model constants and minimum detectable energy")
    print(f"done in {time.perf_counter() - started:.1f} s")
    return 0
