"""Plots a person reads at a glance, and the improvement table, for a discrepancy run."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from transparency_ros.analysis.discrepancy.discover import Report, _phases, split_trials
from transparency_ros.analysis.discrepancy.effects import Cogging, library
from transparency_ros.analysis.discrepancy.model import NominalModel, Trial, make_windows, simulate


def write_report(
    out: Path, model: NominalModel, trials: Sequence[Trial], report: Report, window_s: float
) -> list[Path]:
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: PLC0415
    from matplotlib.figure import Figure  # noqa: PLC0415

    out.mkdir(parents=True, exist_ok=True)
    _, held = split_trials(trials)
    w = make_windows(held, window_s)
    by_name = {e.name: e for e in library()}
    effects, params = [], []
    for f in report.findings:
        effect = by_name[f.effect]
        if isinstance(effect, Cogging):
            effect.cycles_per_rev = int(f.parameters["cycles_per_rev"])
        effects.append(effect)
        params.append(np.array([f.parameters[n] for n in effect.param_names]))
    nominal = simulate(model, [], [], w)
    final = simulate(model, effects, params, w)
    before, after = nominal - w.q, final - w.q
    # the window the found effects improve most: where they show
    gain = np.sqrt(np.mean(before**2, axis=1)) - np.sqrt(np.mean(after**2, axis=1))
    worst = int(np.argmax(gain))

    fig = Figure(figsize=(11, 7), layout="constrained")
    FigureCanvasAgg(fig)
    ax_q, ax_r = fig.subplots(2, 1)
    t = w.t[worst] - w.t[worst, 0]
    ax_q.plot(t, w.q[worst], "k.", ms=3, label="recorded")
    ax_q.plot(t, nominal[worst], color="C3", label="nominal model")
    ax_q.plot(t, final[worst], color="C2", label="with the found effects")
    trial = held[int(w.trial_index[worst])]
    ax_q.set(
        xlabel="time in window [s]",
        ylabel="position [rad]",
        title=f"held-out window the found effects improve most: {trial.name}, "
        f"t = {w.t[worst, 0] - trial.t[0]:.2f} s",
    )
    ax_q.legend(fontsize=8)
    phases = _phases(w)
    names = [n for n in phases if phases[n].any()]
    rms_b = [float(np.sqrt(np.mean(before[phases[n]] ** 2))) for n in names]
    rms_a = [float(np.sqrt(np.mean(after[phases[n]] ** 2))) for n in names]
    x = np.arange(len(names))
    ax_r.bar(x - 0.2, rms_b, 0.4, color="C3", label="nominal")
    ax_r.bar(x + 0.2, rms_a, 0.4, color="C2", label="with the found effects")
    ax_r.set_xticks(x, names)
    ax_r.set(ylabel="held-out simulation RMSE [rad]", title="residual by motion phase")
    ax_r.legend(fontsize=8)
    png = out / "discrepancy.png"
    fig.savefig(png, dpi=110)

    rows = [
        "| step | effect | parameters | where | held-out RMSE before → after [rad] |",
        "|---|---|---|---|---|",
    ]
    for i, f in enumerate(report.findings, 1):
        params_text = ", ".join(f"{k} {v:.4g}" for k, v in f.parameters.items())
        rows.append(
            f"| {i} | {f.effect} | {params_text} | {f.where['phase']} | "
            f"{f.heldout_rmse_before:.4g} → {f.heldout_rmse_after:.4g} |"
        )
    for u in report.unexplained:
        rows.append(f"| - | unexplained | - | {u['where']['phase']} | {u['looks_like']} |")
    table = out / "improvement.md"
    table.write_text("\n".join(rows) + "\n", encoding="utf-8")
    return [png, table]
