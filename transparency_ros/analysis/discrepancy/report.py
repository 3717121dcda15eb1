"""Plots a person reads at a glance, and the improvement table, for a discrepancy run."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from transparency_ros.analysis.discrepancy.findings import Report, parameters_text
from transparency_ros.analysis.discrepancy.problem import Problem


def write_report(out: Path, problem: Problem, report: Report) -> list[Path]:
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: PLC0415
    from matplotlib.figure import Figure  # noqa: PLC0415

    out.mkdir(parents=True, exist_ok=True)
    effects = [e for e, _ in report.fitted]
    params = [p for _, p in report.fitted]
    before = problem.error([], [], True)
    after = problem.error(effects, params, True)
    # the held-out segment the found effects improve most: where they show
    segment, labels = problem.segments()
    count = np.bincount(segment, minlength=len(labels)).clip(1)
    gain = np.sqrt(np.bincount(segment, before**2, len(labels)) / count) - np.sqrt(
        np.bincount(segment, after**2, len(labels)) / count
    )
    trace = problem.trace(effects, params, int(np.argmax(gain)))

    fig = Figure(figsize=(11, 7), layout="constrained")
    FigureCanvasAgg(fig)
    ax_q, ax_r = fig.subplots(2, 1)
    ax_q.plot(trace.t, trace.recorded, "k.", ms=3, label="recorded")
    ax_q.plot(trace.t, trace.nominal, color="C3", label="nominal model")
    ax_q.plot(trace.t, trace.final, color="C2", label="with the found effects")
    ax_q.set(
        xlabel="time [s]",
        ylabel=trace.ylabel,
        title=f"held-out segment the found effects improve most: {trace.title}",
    )
    ax_q.legend(fontsize=8)
    phases = problem.phases()
    names = [n for n in phases if phases[n].any()]
    rms_b = [float(np.sqrt(np.mean(before[phases[n]] ** 2))) for n in names]
    rms_a = [float(np.sqrt(np.mean(after[phases[n]] ** 2))) for n in names]
    x = np.arange(len(names))
    ax_r.bar(x - 0.2, rms_b, 0.4, color="C3", label="nominal")
    ax_r.bar(x + 0.2, rms_a, 0.4, color="C2", label="with the found effects")
    ax_r.set_xticks(x, names)
    ax_r.set(ylabel="held-out simulation RMSE [rad]", title="residual by phase")
    ax_r.legend(fontsize=8)
    png = out / "discrepancy.png"
    fig.savefig(png, dpi=110)

    rows = [
        "| step | effect | parameters | where | held-out RMSE before → after [rad] |",
        "|---|---|---|---|---|",
    ]
    for i, f in enumerate(report.findings, 1):
        params_text = parameters_text(f)
        rows.append(
            f"| {i} | {f.effect} | {params_text} | {f.where['phase']} | "
            f"{f.heldout_rmse_before:.4g} → {f.heldout_rmse_after:.4g} |"
        )
    for u in report.unexplained:
        rows.append(f"| - | unexplained | - | {u['where']['phase']} | {u['looks_like']} |")
    if report.notes:
        rows += ["", "Notes on the data:", "", *(f"- {note}" for note in report.notes)]
    table = out / "improvement.md"
    table.write_text("\n".join(rows) + "\n", encoding="utf-8")
    return [png, table]
