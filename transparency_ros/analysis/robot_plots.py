"""The plot of `transparency detect --report`: per joint, the residual against its threshold,
the true external torque where labelled, and the detections, over time."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from transparency_ros.analysis.robot_data import JointRecording
from transparency_ros.analysis.robot_detect import Detection


def plot_detection(out: Path, det: Detection, rec: JointRecording) -> Path:
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: PLC0415
    from matplotlib.figure import Figure  # noqa: PLC0415

    out.mkdir(parents=True, exist_ok=True)
    n = len(det.joints)
    fig = Figure(figsize=(10, 2.6 * n), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(n, 1, sharex=True, squeeze=False)[:, 0]
    for j, ax in enumerate(axes):
        ax.plot(det.t_s, det.residual[:, j], lw=0.7, color="C0", label="residual")
        limit = np.where(np.isfinite(det.threshold[:, j]), det.threshold[:, j], np.nan)
        ax.plot(det.t_s, limit, lw=0.8, color="C3", label="threshold")
        ax.plot(det.t_s, -limit, lw=0.8, color="C3")
        if rec.label is not None:
            ax.plot(det.t_s, rec.label[:, j], lw=1.0, color="k", label="true external")
        for k, t in enumerate(det.onsets_s[j]):
            ax.axvline(t, color="C2", lw=0.8, label="detection" if k == 0 else None)
        ax.set_ylabel(f"{det.joints[j]} [N m]")
        ax.legend(loc="upper right", fontsize=7)
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(det.recording)
    path = out / f"{det.recording}.png"
    fig.savefig(path, dpi=110)
    return path
