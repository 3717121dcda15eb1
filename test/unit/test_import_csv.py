"""``transparency import-csv`` on the CSVs users have: one clear line and status 2 for a file it
cannot turn into a bag, and nothing written (not even the output directory)."""

from __future__ import annotations

from pathlib import Path

import pytest

from transparency_ros.cli import main

HEADER = "time,position,velocity,torque\n"
ROBOT_HEADER = "time,pos_meas1,vel_meas1,tau_con1\n"


@pytest.mark.parametrize(
    ("text", "joints", "expected"),
    [
        ("", None, "empty file (no header)"),
        (HEADER, None, "0 data rows; at least 2 are needed"),
        (HEADER + "0,0,0,0\n", None, "1 data rows; at least 2 are needed"),
        (HEADER + "0,0,0,0\n0.002,0,0,0\n0.001,0,0,0\n", None,
         "time column 'time' goes backwards at row 4: 0.001 after 0.002 (1 such row)"),
        (HEADER + "0,0,0,0\n0,0,0,0\n", None, "time column 'time' repeats at row 3"),
        (HEADER + "0,0,0\n0.1,0,0\n", None, "rows of 3 values under 4 columns"),
        ("", "a", "empty file"),
        (ROBOT_HEADER, "a", "fewer than 2 data rows"),
        (ROBOT_HEADER + "0,0,0,0\n0.002,0,0,0\n0.001,0,0,0\n", "a",
         "time column 'time' goes backwards at row 4: 0.001 after 0.002"),
    ],
)  # fmt: skip
def test_a_csv_that_cannot_be_a_bag_is_one_line_and_nothing_is_written(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], text: str, joints: str | None,
    expected: str,
) -> None:  # fmt: skip
    csv = tmp_path / "run.csv"
    csv.write_text(text)
    out = tmp_path / "bags"
    args = ["import-csv", str(csv), "--out", str(out)] + (["--joints", joints] if joints else [])
    assert main(args) == 2
    captured = capsys.readouterr()
    assert captured.err.strip() == f"transparency import-csv: error: {csv}: {expected}" or (
        expected in captured.err and len(captured.err.strip().splitlines()) == 1
    ), captured.err
    assert "Traceback" not in captured.err and "Warning" not in captured.err
    assert not out.exists()


def test_a_repeated_stamp_in_a_robots_csv_is_dropped_with_a_note(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    csv = tmp_path / "run.csv"
    csv.write_text(ROBOT_HEADER + "0,0,0,0\n0.002,0,0,0\n0.002,0,0,0\n0.004,0,0,0\n")
    assert main(["import-csv", str(csv), "--out", str(tmp_path / "bags"), "--joints", "a"]) == 0
    captured = capsys.readouterr()
    assert "1 row whose time does not increase dropped" in captured.err + captured.out
