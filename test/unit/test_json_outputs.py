"""Every ``--json`` of every subcommand is strict JSON (RFC 8259: no NaN or Infinity, which
jq, JavaScript, Go and Rust refuse; a missing number is null), and ``detect --json`` gives what a
script needs: per recording and joint the contacts, and the scores only when there are labels."""

from __future__ import annotations

import contextlib
import io
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from transparency_ros.cli import build_parser, main
from transparency_ros.core import strict_json
from transparency_ros.synth.robots import chain_urdf

ROOT = Path(__file__).resolve().parents[2]
SHARED = Path(__file__).resolve().parents[1] / "data" / "double_pendulum"
BAGS = Path(__file__).resolve().parents[1] / "data" / "external_bags"


def run_json(args: list[str]) -> object:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main([*args, "--json"])
    assert code == 0, (args, err.getvalue())
    return strict_json.loads(out.getvalue())


def test_the_strict_encoder_writes_null_for_what_is_not_a_number() -> None:
    data = {"recall": math.nan, "a": [np.float64(np.inf), np.int64(3), np.bool_(True)],
            "p": Path("x/y"), "t": (1.5, -math.inf)}  # fmt: skip
    text = strict_json.dumps(data)
    assert strict_json.loads(text) == {
        "recall": None, "a": [None, 3, True], "p": "x/y", "t": [1.5, None]
    }  # fmt: skip
    with pytest.raises(ValueError, match="NaN"):
        strict_json.loads('{"x": NaN}')
    with pytest.raises(TypeError, match="not JSON data"):
        strict_json.dumps({"x": object()})


def subcommands_with_json() -> set[str]:
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    return {
        name for name, p in sub.choices.items()  # type: ignore[union-attr]
        if any("--json" in a.option_strings for a in p._actions)
    }  # fmt: skip


def test_every_json_output_parses_strictly(tmp_path: Path) -> None:
    """One run of each subcommand that has --json, on small inputs; the list of subcommands is
    the parser's, so a new --json without a case here fails."""
    bags = tmp_path / "T2822"
    shutil.copytree(ROOT / "bags" / "T2822", bags)
    pendubot = [str(SHARED / f"pendubot_{n}.csv.xz") for n in ("clean_01", "pert_01")]
    pendubot_clean = [str(SHARED / f"pendubot_clean_0{k}.csv.xz") for k in (1, 2)]
    cases = {
        "model": [["model", "--actuator", "U10GB", "--energy", "0.001", "1"],
                  ["model", "--curves", "--points", "20"]],
        "compare-estimators": [["compare-estimators", "--actuator", "U10DD", "--pulses", "3"]],
        "feelcage": [["feelcage", "--engine", "core", "--actuators", "U10DD", "--balls",
                      "rubber"]],
        "eval": [["eval", str(bags)]],
        "salvage": [["salvage", str(BAGS / "rosbag2_jazzy_mcap_cdr_test_v7"), "--out",
                     str(tmp_path / "salvaged")]],
        "discrepancy": [["discrepancy", str(bags)],
                        ["discrepancy", *pendubot_clean, "--urdf", str(SHARED / "pendubot.urdf")]],
        "assay": [["assay", *pendubot_clean, "--urdf", str(SHARED / "pendubot.urdf"), "--folds",
                   "2", "--placements", "1", "--detectors", "textbook"]],
        "detect": [["detect", pendubot[1], "--urdf", str(SHARED / "pendubot.urdf"), "--method",
                    "textbook", "--clean", pendubot[0], "--labels", "tau_pert{}"]],
    }  # fmt: skip
    assert set(cases) == subcommands_with_json()
    for runs in cases.values():
        for args in runs:
            run_json(args)  # parsed strictly, or the test fails here


def test_detect_json_gives_contacts_per_recording_and_joint(tmp_path: Path) -> None:
    """Onsets with their releases and peaks, per recording and joint; with labels the scores
    and the missed pulses as data; without labels no scores (onsets are not false alarms)."""
    urdf = str(SHARED / "pendubot.urdf")
    clean, pert = (str(SHARED / f"pendubot_{n}.csv.xz") for n in ("clean_01", "pert_01"))
    args = ["detect", pert, "--urdf", urdf, "--method", "textbook", "--clean", clean]
    report = run_json([*args, "--labels", "tau_pert{}"])
    assert isinstance(report, dict)
    assert report["method"] == "textbook" and report["residual_unit"] == "N m"
    (rec,) = report["recordings"]
    assert rec["recording"] == "pendubot_pert_01" and rec["labelled"] is True
    assert set(rec["joints"]) == {"Joint1", "Joint2"}
    contacts = [c for j in rec["joints"].values() for c in j["contacts"]]
    assert contacts, "no contact at all on a disturbed run"
    for c in contacts:
        assert set(c) == {"onset_s", "release_s", "peak_residual"}
        assert c["release_s"] is None or c["release_s"] > c["onset_s"]
        assert isinstance(c["peak_residual"], float) and c["peak_residual"] != 0.0
    scores = report["scores"]
    assert set(scores) == {"Joint1", "Joint2"}
    for joint, s in scores.items():
        assert s["found"] + len(s["missed"]) == s["pulses"], joint
        for m in s["missed"]:
            assert m["joint"] == joint and m["recording"] == "pendubot_pert_01"
            assert m["start_s"] <= m["half_s"] <= m["end_s"] and m["peak_nm"] > 0
    # the onsets are the text output's
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main([*args, "--labels", "tau_pert{}"]) == 0
    text = {line.split(":")[0]: line.split("[s] ")[1] for line in out.getvalue().splitlines()
            if "contact onsets" in line}  # fmt: skip
    for joint, data in rec["joints"].items():
        printed = text[f"pendubot_pert_01 {joint}"]
        onsets = [f"{c['onset_s']:.3f}" for c in data["contacts"]]
        assert printed == (", ".join(onsets) or "none")
    unlabelled = run_json(args)
    assert isinstance(unlabelled, dict) and unlabelled["scores"] is None
    assert unlabelled["recordings"] == [{**rec, "labelled": False}]
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(args) == 0
    assert "false alarms" not in out.getvalue()


def test_detect_refuses_labels_no_recording_has_and_another_robots_urdf(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    clean, pert = (str(SHARED / f"pendubot_{n}.csv.xz") for n in ("clean_01", "pert_01"))
    urdf = str(SHARED / "pendubot.urdf")
    args = ["detect", pert, "--urdf", urdf, "--method", "textbook", "--clean", clean]
    assert main([*args, "--labels", "nope{}"]) == 2
    err = [e for e in capsys.readouterr().err.strip().splitlines() if not e.startswith("note:")]
    assert err == ["transparency detect: error: --labels nope{}: no recording has them (a CSV's "
                   "column 'nope1', a bag's topic /true_external_effort)"]  # fmt: skip
    one_joint = tmp_path / "one.urdf"
    one_joint.write_text(chain_urdf(1))  # a robot with one joint, j0
    assert main(["detect", pert, "--urdf", str(one_joint), "--method", "textbook", "--clean",
                 clean]) == 2  # fmt: skip
    err = [e for e in capsys.readouterr().err.strip().splitlines() if not e.startswith("note:")]
    assert len(err) == 1 and "columns for 2 joints" in err[0] and "the URDF has 1" in err[0], err
