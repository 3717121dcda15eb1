"""``transparency eval``: drop-test bags -> t_r, Delta E per trial, Fig. 2 against the model."""

from __future__ import annotations

import argparse
import math
import sys
from typing import Any

from transparency_ros.analysis.drop_eval import evaluate, summarise
from transparency_ros.bag.errors import BagReadError
from transparency_ros.commands.outputs import output_file
from transparency_ros.core import strict_json


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "eval",
        help="evaluate drop-test bags: Fig. 2a/2b measured against the model",
        description=(
            "Read drop-test bags (the bag contract; any rosbag2 storage), find t_t from the load "
            "cell, T from the shuttle velocity, t_e from the recorded /contact (or the estimator "
            "replayed offline), and print t_r, v_s,e, Delta E, F_mu, F_est per trial and a "
            "summary per actuator against the contact model."
        ),
    )
    p.add_argument("bags", nargs="+", metavar="BAG_OR_DIR")
    p.add_argument("--json", action="store_true", help="print machine-readable JSON")
    p.add_argument("--plot", metavar="PNG", help="write Fig. 2a/2b with the measured points")
    p.set_defaults(func=run)


def _f(value: float | None, scale: float = 1.0, spec: str = ".3g") -> str:
    """A figure, or "-" where there is none (None, NaN)."""
    return "-" if value is None or math.isnan(value) else format(value * scale, spec)


def run(args: argparse.Namespace) -> int:
    if args.plot:
        output_file(args.plot, "--plot")
    terminal = sys.stderr.isatty()
    skips: list[str] = []

    def progress(i: int, n: int, bag: Any) -> None:
        if n > 1 and terminal:  # one line, rewritten
            print(f"\r[{i}/{n}] {bag}", end="" if i < n else "\n", file=sys.stderr, flush=True)
        elif n > 1:  # a pipe or a log: a line per bag
            print(f"[{i}/{n}] {bag}", file=sys.stderr, flush=True)

    def skipped(err: Exception) -> None:
        skips.append(str(err))
        prefix = "\n" if terminal else ""  # (below the progress line)
        print(f"{prefix}skipped: {err}", file=sys.stderr, flush=True)

    results = evaluate(args.bags, progress, skipped)
    if skips:
        print(f"{len(skips)} bag(s) skipped, {len(results)} evaluated", file=sys.stderr)
    if not results:
        raise BagReadError(f"no complete trial in {', '.join(args.bags)}")
    summary = summarise(results)
    if args.plot:
        from transparency_ros.analysis.fig2 import model_curves, plot_fig2  # noqa: PLC0415
        from transparency_ros.core.contact_model import model_for  # noqa: PLC0415

        curves = model_curves([model_for(s.actuator) for s in summary])
        title = (
            f"Fig. 2 from {len(results)} drop-test bags: points measured (open: not detected), "
            "lines the contact model eq. (2)-(4); dotted: model's minimum detectable energy"
        )
        plot_fig2(curves, args.plot, title=title, measured=results)
        print(f"wrote {args.plot}", file=sys.stderr)
    if args.json:
        strict_json.dump({"trials": [r.as_dict() for r in results],
                          "summary": [s.__dict__ for s in summary], "skipped": skips},
                         sys.stdout)  # fmt: skip
        return 0
    print(f"{'actuator':<8} {'h [m]':>6} {'T [J]':>7} {'t_r [ms]':>9} {'v_s,e [m/s]':>11} "
          f"{'ΔE [J]':>8} {'F_mu [N]':>9} {'F_est [N]':>9}  t_e from")  # fmt: skip
    for r in results:
        print(f"{r.actuator:<8} {r.drop_height_m:>6.3f} {_f(r.energy_j):>7} "
              f"{_f(r.t_r_s, 1e3):>9} {_f(r.v_s_e_m_s):>11} {_f(r.delta_e_j):>8} "
              f"{_f(r.f_measured_n):>9} {_f(r.f_estimated_n):>9}  {r.estimate_source}")  # fmt: skip
    print()
    for s in summary:
        print(
            f"{s.actuator}: {s.detected}/{s.trials} detected; smallest detected T "
            f"{_f(s.min_detected_energy_j)} J, largest missed {_f(s.max_missed_energy_j)} J "
            f"(model T_min {s.model_min_detectable_energy_j:.3g} J); ΔE/T slope "
            f"{_f(s.delta_e_slope)} (model {s.model_delta_e_slope:.3g}); t_r - model, median "
            f"{_f(s.t_r_error_median_ms)} ms"
        )
    return 0
