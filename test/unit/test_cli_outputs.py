"""What commands write and where: a campaign with a damaged bag is evaluated but for it, a
plot path with a typo in its directory is refused (not created), and progress goes to a pipe
as whole lines (no carriage returns in logs)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from transparency_ros.cli import main
from transparency_ros.core import strict_json

ROOT = Path(__file__).resolve().parents[2]


def test_eval_reports_a_damaged_bag_and_evaluates_the_rest(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    campaign = tmp_path / "T2822"
    shutil.copytree(ROOT / "bags" / "T2822", campaign)
    damaged = sorted(campaign.iterdir())[0]
    mcap = next(damaged.glob("*.mcap"))
    mcap.write_bytes(mcap.read_bytes()[: mcap.stat().st_size // 2])  # cut off mid-recording
    assert main(["eval", str(campaign), "--json"]) == 0
    captured = capsys.readouterr()
    report = strict_json.loads(captured.out)
    assert len(report["trials"]) == len(list(campaign.iterdir())) - 1
    (skip,) = report["skipped"]
    assert str(damaged) in skip and "salvage" in skip
    assert f"skipped: {damaged}" in captured.err
    assert "1 bag(s) skipped, 1 evaluated" in captured.err
    assert "\r" not in captured.err  # not a terminal: a line per bag
    assert "[1/2]" in captured.err and "[2/2]" in captured.err


@pytest.mark.parametrize(
    "args",
    [["model", "--curves", "--points", "10", "--plot"], ["eval", str(ROOT / "bags" / "T2822"),
                                                         "--plot"]],
)  # fmt: skip
def test_a_plot_in_a_directory_that_does_not_exist_is_refused_before_any_work(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str]
) -> None:
    target = tmp_path / "no_such_dir" / "fig.png"
    assert main([*args, str(target)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"transparency {args[0]}: error: --plot {target}: directory "
                   f"{target.parent} does not exist"]  # fmt: skip
    assert not target.parent.exists()


def test_messages_show_numbers_as_typed(capsys: pytest.CaptureFixture[str]) -> None:
    """Not "np.float64(-1.0)", "1 replies" or "median nan ms"."""
    from transparency_ros.commands.evaluate import _f  # noqa: PLC0415
    from transparency_ros.ros.actuator_driver.diagnostics import late_message  # noqa: PLC0415

    assert main(["model", "--actuator", "U10DD", "--energy", "-1"]) == 2
    err = capsys.readouterr().err
    assert "got -1.0" in err and "np.float64" not in err
    assert (late_message(1, 1, 0.001) or "").startswith("1 of 1 reply late")
    assert _f(float("nan"), 1e3) == "-" and _f(None) == "-" and _f(0.5) == "0.5"
