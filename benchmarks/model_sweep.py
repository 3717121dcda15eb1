"""Model sweeps: the closed-form energy-delay curves (eq. 2, Fig. 2) against scipy's solve_ivp.

    .venv/bin/python benchmarks/model_sweep.py [--energies 10000] [--ivp-every 25] [--out DIR]

For each of the four actuators, ``ContactModel.solve`` evaluates detection, delay t_r and speed
at detection for ``--energies`` collision energies (log-spaced, 1 mJ to 10 J) in one vectorised
call (best of 5). The peer integrates eq. (2) with ``solve_ivp`` (DOP853, rtol 1e-12, events at
the threshold and at the end of the first swing: the reference of test/unit/test_contact_model)
on every ``--ivp-every``-th of the same energies; its time per point is scaled to the whole
sweep, and the two are compared point by point (detection must agree; t_r to a relative 1e-6).
Writes benchmarks/results/model_sweep.md and .json.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from _results import write_results

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from test.unit.test_contact_model import ACTUATORS, ode_reference  # noqa: E402
from transparency_ros.core.contact_model import model_for  # noqa: E402


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--energies", type=int, default=10_000)
    parser.add_argument("--ivp-every", type=int, default=25, help="solve_ivp on every N-th point")
    parser.add_argument("--out", default=str(Path(__file__).parent / "results"))
    args = parser.parse_args()
    energies = np.geomspace(1e-3, 10.0, args.energies)
    rows = []
    for actuator in ACTUATORS:
        m = model_for(actuator)
        best = np.inf
        for _ in range(5):
            started = time.perf_counter()
            r = m.solve(energies)
            best = min(best, time.perf_counter() - started)
        picked = np.arange(0, energies.size, args.ivp_every)
        started = time.perf_counter()
        ref = [ode_reference(m, float(energies[i])) for i in picked]
        ivp_per_point = (time.perf_counter() - started) / picked.size
        agree = all(bool(r.detected[i]) == d for i, (d, *_rest) in zip(picked, ref, strict=True))
        errors = [
            abs(r.t_r_s[i] - t_r) / t_r
            for i, (d, t_r, *_rest) in zip(picked, ref, strict=True)
            if d and t_r > 0
        ]
        rows.append(
            {
                "actuator": actuator,
                "energies": int(energies.size),
                "closed_form_s": best,
                "solve_ivp_points": int(picked.size),
                "solve_ivp_s_per_point": ivp_per_point,
                "solve_ivp_s_whole_sweep": ivp_per_point * energies.size,
                "speedup": ivp_per_point * energies.size / best,
                "detection_agrees": agree,
                "t_r_max_rel_error": max(errors) if errors else float("nan"),
            }
        )
        row = rows[-1]
        print(
            f"{actuator}: closed form {best * 1e3:.1f} ms for {energies.size} energies; "
            f"solve_ivp {ivp_per_point * 1e3:.2f} ms/point ({picked.size} points) -> "
            f"{row['solve_ivp_s_whole_sweep']:.0f} s for the sweep, x{row['speedup']:.0f}; "
            f"detection agrees: {agree}; t_r max rel. error {row['t_r_max_rel_error']:.1e}",
            flush=True,
        )
    lines = [
        f"Model sweep: {args.energies} energies per actuator, closed form (best of 5) against "
        f"solve_ivp (DOP853, rtol 1e-12) on every {args.ivp_every}th point, scaled to the sweep",
        "",
        "| actuator | closed form [ms] | solve_ivp [ms/point] | solve_ivp, whole sweep [s] "
        "| speed-up | detection agrees | t_r max rel. error |",
        "|---|---|---|---|---|---|---|",
        *[
            f"| {r['actuator']} | {r['closed_form_s'] * 1e3:.1f} "
            f"| {r['solve_ivp_s_per_point'] * 1e3:.2f} | {r['solve_ivp_s_whole_sweep']:.0f} "
            f"| {r['speedup']:.0f}x | {'yes' if r['detection_agrees'] else 'NO'} "
            f"| {r['t_r_max_rel_error']:.1e} |"
            for r in rows
        ],
        "",
        "(`.venv/bin/python benchmarks/model_sweep.py`)",
    ]
    write_results(args.out, "model_sweep", lines, rows)
    return 0 if all(r["detection_agrees"] for r in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
