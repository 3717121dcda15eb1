"""The `transparency` command: subcommands, --help, JSON output, plots and clear errors."""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from transparency_ros.cli import main
from transparency_ros.core import strict_json

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def run_cli(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_model_json_single_point(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run_cli(capsys, "model", "--actuator", "U10DD", "--energy", "0.5", "--json")
    assert code == 0
    data = strict_json.loads(out)
    assert data["actuator"] == "U10DD" and data["regime"] == "underdamped"
    (row,) = data["results"]
    assert row["energy_j"] == 0.5 and row["detected"] is True
    assert 0 < row["t_r_s"] < 0.05
    assert 0 < row["delta_e_j"] < 0.5
    assert row["omega_c_rad_s"] > 0 and 0 < row["v_s_e_m_s"] < row["v_s_t_m_s"]


def test_model_json_not_detected_is_null(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run_cli(
        capsys, "model", "--actuator", "U10GB", "--actuator", "EC60", "--energy", "0.5", "--json"
    )
    assert code == 0
    u10gb, ec60 = strict_json.loads(out)
    assert u10gb["results"][0]["detected"] is False
    assert u10gb["results"][0]["t_r_s"] is None and u10gb["results"][0]["delta_e_j"] is None
    assert ec60["results"][0]["detected"] is True


def test_model_table_output(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run_cli(capsys, "model", "--actuator", "T2822", "--energy", "0.1", "5")
    assert code == 0
    assert "T2822" in out and "overdamped" in out
    lines = [line.split() for line in out.splitlines() if line.strip().startswith(("0.1", "5"))]
    assert lines[0][1] == "no" and lines[1][1] == "yes"


def test_model_curves_plot_and_json(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    png = tmp_path / "fig2.png"  # (a directory that does not exist is refused: test_cli_outputs)
    code, out, err = run_cli(
        capsys, "model", "--curves", "--plot", str(png), "--points", "50", "--json"
    )
    assert code == 0
    assert png.read_bytes()[:8] == PNG_MAGIC and png.stat().st_size > 20_000
    assert str(png) in err
    curves = strict_json.loads(out)["curves"]
    assert [c["actuator"] for c in curves] == ["U10DD", "EC60", "T2822", "U10GB"]
    slopes = [c["delta_e_slope"] for c in curves]
    assert slopes == sorted(slopes)
    for c in curves:
        assert len(c["energy_j"]) == len(c["t_r_s"]) == len(c["delta_e_j"]) >= 50


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["model", "--actuator", "X1", "--energy", "1"], r"unknown actuator\(s\) \['X1'\]"),
        (["model", "--actuator", "U10DD"], "give --energy"),
        (["model", "--energy", "1"], "give --actuator NAME"),
        (
            ["model", "--actuator", "U10DD", "--energy", "-1"],
            "collision energy must be finite and >= 0",
        ),
        (
            ["model", "--actuator", "U10DD", "--energy", "1", "--plot", "x.png"],
            "--plot needs --curves",
        ),
        (
            ["model", "--actuator", "U10DD", "--energy", "1", "--k-s", "-2"],
            "k_s_nm_per_rad must be",
        ),
        (["model", "--curves", "--energy-range", "5", "1"], "energy range must satisfy"),
    ],
)
def test_errors_are_one_clear_line(
    capsys: pytest.CaptureFixture[str], argv: list[str], message: str
) -> None:
    code, out, err = run_cli(capsys, *argv)
    assert code == 2 and out == ""
    assert err.startswith("transparency model: error: ")
    assert len(err.strip().splitlines()) == 1
    assert re.search(message, err), err


def test_help_lists_subcommands(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as info:
        main(["--help"])
    assert info.value.code == 0
    out = capsys.readouterr().out
    assert "model" in out and "demo" in out


def test_python_dash_m_and_console_script() -> None:
    env = {**os.environ}
    via_module = subprocess.run(
        [sys.executable, "-m", "transparency_ros", "model", "--help"],
        capture_output=True,
        text=True,
        env=env,
        check=True,
    )
    assert "--energy" in via_module.stdout and "examples:" in via_module.stdout
    script = shutil.which("transparency", path=str(Path(sys.executable).parent))
    assert script, "console script `transparency` not installed next to the interpreter"
    via_script = subprocess.run([script, "--version"], capture_output=True, text=True, check=True)
    assert via_script.stdout.startswith("transparency 0.1.0")


def test_demo_produces_what_it_lists(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run_cli(capsys, "demo", "--out", str(tmp_path), "--no-ros")
    assert code == 0
    listed = [line.split()[0] for line in out.splitlines() if line.startswith("  " + str(tmp_path))]
    assert len(listed) == 3
    for path in listed:
        assert Path(path).stat().st_size > 0
    summary = strict_json.loads((tmp_path / "actuators_summary.json").read_text())
    assert [s["actuator"] for s in summary] == ["U10DD", "EC60", "T2822", "U10GB"]


STARTED_WITH_SIGINT_IGNORED = """
import os, signal, sys, time
signal.signal(signal.SIGINT, signal.SIG_IGN)  # as a script's background job starts
from transparency_ros import cli

class Waits:  # a subcommand that is interrupted while it works
    @staticmethod
    def register(subparsers):
        subparsers.add_parser("wait").set_defaults(func=Waits.run)

    @staticmethod
    def run(args):
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(5.0)
        print("SIGINT was ignored")
        return 0

cli.SUBCOMMANDS = (Waits,)
code = cli.main(["wait"])
assert signal.getsignal(signal.SIGINT) == signal.SIG_IGN, "disposition not restored"
sys.exit(code)
"""


def test_sigint_stops_a_command_started_with_sigint_ignored() -> None:
    """A script's background job inherits SIGINT ignored; rclpy shuts its contexts down on
    SIGINT all the same, so a command unwinds as for Ctrl-C instead of running on with dead
    contexts, and puts the disposition back when it returns."""
    done = subprocess.run(
        [sys.executable, "-c", STARTED_WITH_SIGINT_IGNORED],
        capture_output=True, text=True, timeout=60, check=False,
    )  # fmt: skip
    assert done.returncode == 128 + signal.SIGINT, (done.stdout, done.stderr)
    assert "transparency wait: stopped by SIGINT" in done.stderr
    assert "SIGINT was ignored" not in done.stdout
