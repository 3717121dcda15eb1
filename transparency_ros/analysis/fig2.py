"""Fig. 2 of the paper from the contact model: t_r vs T (2a) and Delta E vs T (2b)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from transparency_ros.core.contact_model import ContactModel, ContactResult, FloatArray
from transparency_ros.core.errors import ModelError

# One colour per Table 1 actuator, in order of gearing, so every figure reads the same way.
ACTUATOR_COLOURS = {"U10DD": "#1b9e77", "EC60": "#d95f02", "T2822": "#7570b3", "U10GB": "#e7298a"}


@dataclass(frozen=True)
class ModelCurve:
    """Energy-delay curve of one actuator. Arrays have shape (N,), NaN where not detected."""

    model: ContactModel
    min_detectable_energy_j: float
    result: ContactResult

    @property
    def delta_e_slope(self) -> float:
        """Least-squares slope of Delta E vs T over the detected part of the curve [J/J]."""
        r = self.result
        ok = r.detected
        if np.count_nonzero(ok) < 2:
            return math.nan
        slope, _ = np.polyfit(r.energy_j[ok], r.delta_e_j[ok], 1)
        return float(slope)


def energy_grid(
    low_j: float, high_j: float, points: int, asymptotes: Sequence[float]
) -> FloatArray:
    """Log-spaced energies plus points packed just above each asymptote (steep there)."""
    if not (0 < low_j < high_j) or points < 2:
        raise ModelError(
            f"energy range must satisfy 0 < low < high and points >= 2, got "
            f"{low_j}, {high_j}, {points}"
        )
    grid = [np.geomspace(low_j, high_j, points)]
    for t_min in asymptotes:
        near = t_min * (1.0 + np.geomspace(1e-6, 1.0, max(points // 8, 8)))
        grid.append(near[(near >= low_j) & (near <= high_j)])
    return np.unique(np.concatenate(grid))


def model_curves(
    models: Sequence[ContactModel], low_j: float = 0.01, high_j: float = 10.0, points: int = 400
) -> list[ModelCurve]:
    """Evaluate every model on a shared energy grid."""
    t_mins = [m.min_detectable_energy() for m in models]
    grid = energy_grid(low_j, high_j, points, t_mins)
    return [ModelCurve(m, t_min, m.solve(grid)) for m, t_min in zip(models, t_mins, strict=True)]


def plot_fig2(
    curves: Sequence[ModelCurve],
    path: str | Path,
    title: str | None = None,
    measured: Sequence[Any] = (),
) -> Path:
    """Write Fig. 2a/2b (model curves) as a PNG. Headless: no display or pyplot state needed.

    ``measured``: trials (``TrialMetrics`` of :mod:`transparency_ros.analysis.drop_eval`) drawn
    as points over the curves: detected trials as filled markers; missed ones at the bottom of
    panel (a) as open markers."""
    # matplotlib is imported here, not at the top: the CLI starts fast when not plotting.
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: PLC0415
    from matplotlib.figure import Figure  # noqa: PLC0415
    from matplotlib.ticker import FuncFormatter  # noqa: PLC0415

    out = Path(path)  # (its directory is the caller's to make: a typo is not created)
    fig = Figure(figsize=(11, 4.6), layout="constrained")
    FigureCanvasAgg(fig)
    ax_t, ax_e = fig.subplots(1, 2)
    for curve in curves:
        r = curve.result
        name = curve.model.actuator
        colour = ACTUATOR_COLOURS.get(name)
        label = f"{name} (T_min {curve.min_detectable_energy_j:.3g} J)"
        ax_t.plot(r.energy_j, r.t_r_s * 1e3, color=colour, label=label)
        ax_e.plot(r.energy_j, r.delta_e_j, color=colour, label=name)
        for ax in (ax_t, ax_e):
            ax.axvline(curve.min_detectable_energy_j, color=colour, ls=":", lw=1)
    for trial in measured:
        colour = ACTUATOR_COLOURS.get(trial.actuator)
        if trial.energy_j is None:
            continue
        if trial.detected:
            ax_t.plot(trial.energy_j, trial.t_r_s * 1e3, "o", color=colour, ms=5, mec="k", mew=0.5)
            if trial.delta_e_j is not None and trial.delta_e_j > 0:
                ax_e.plot(trial.energy_j, trial.delta_e_j, "o", color=colour, ms=5, mec="k",
                          mew=0.5)  # fmt: skip
        else:
            ax_t.plot(trial.energy_j, 0.3, "o", mfc="none", color=colour, ms=6)
    energies = np.concatenate([c.result.energy_j for c in curves])
    ax_e.plot(energies, energies, color="0.6", lw=0.8, ls="--", label="ΔE = T (all energy lost)")
    ax_t.set(
        xscale="log",
        yscale="log",
        xlabel="collision energy T [J]",
        ylabel="detection delay t_r [ms]",
        title="(a) detection delay",
    )
    ax_e.set(
        xscale="log",
        yscale="log",
        xlabel="collision energy T [J]",
        ylabel="energy lost before detection ΔE [J]",
        title="(b) energetic cost of proprioception",
    )
    plain = FuncFormatter(lambda value, _pos: f"{value:g}")
    for ax in (ax_t, ax_e):
        ax.xaxis.set_major_formatter(plain)
        ax.yaxis.set_major_formatter(plain)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    if curves:
        m = curves[0].model
        fig.suptitle(
            title
            or (
                f"Contact model, eq. (2)-(4): k_s = {m.k_s_nm_per_rad:g} N·m/rad, "
                f"threshold {m.threshold_rad:g} rad, r = {m.arm_length_m:g} m; "
                "dotted: minimum detectable energy"
            ),
            fontsize=10,
        )
    fig.savefig(out, dpi=120)
    return out
