"""`make demo` end to end: model figures plus the real actuator_driver process."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.ros


def test_demo_runs_the_driver_and_lists_what_it_made(tmp_path: Path) -> None:
    exe = Path(sys.executable).parent / "transparency"
    out = subprocess.run(
        [str(exe), "demo", "--out", str(tmp_path), "--heights", "0.05,0.4"],
        capture_output=True,
        text=True,
        timeout=240,
        check=False,
    )
    assert out.returncode == 0, out.stdout + out.stderr
    listed = [
        Path(line.split()[0])
        for line in out.stdout.splitlines()
        if line.startswith("  " + str(tmp_path))
    ]
    assert {p.name for p in listed} == {
        "fig2_model.png",
        "fig2_model.json",
        "actuators_summary.json",
        "driver_step.png",
        "driver_step.csv",
        "rig_bags",
        "fig2_measured.png",
        "fig2_measured.json",
    }
    assert all(p.stat().st_size > 0 for p in listed if p.is_file())
    assert len(list((tmp_path / "rig_bags").rglob("metadata.yaml"))) == 8
    assert "the simulated motor was disabled" in out.stdout
    rows = (tmp_path / "driver_step.csv").read_text().splitlines()
    assert rows[0] == "t_s,position_rad,velocity_rad_s,effort_nm" and len(rows) > 1000
    final = float(rows[-1].split(",")[1])
    assert 0.95 < final < 1.0  # short of the command by the Coulomb dead band
