"""The reference bags in bags/: `transparency eval` reproduces the figures stored with them, and
each bag replayed (by the `bag_replay` executable) into a live contact_estimator gives the onset
the recording holds, to within one sample."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")
from geometry_msgs.msg import WrenchStamped  # noqa: E402
from rclpy.context import Context  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402

from test.ros.conftest import Spinner, wait_for  # noqa: E402
from transparency_ros.analysis.drop_eval import evaluate, offline_onset  # noqa: E402
from transparency_ros.bag.reader import joint_series, open_bag  # noqa: E402
from transparency_ros.ros.contact_estimator import ContactEstimatorNode  # noqa: E402
from transparency_ros.ros.conversions import stamp_to_ns  # noqa: E402

pytestmark = pytest.mark.ros
ROOT = Path(__file__).resolve().parents[2]
BAGS = sorted(p.parent for p in (ROOT / "bags").rglob("metadata.yaml"))


def test_reference_bags_stay_small_and_cover_every_actuator() -> None:
    size = sum(f.stat().st_size for f in (ROOT / "bags").rglob("*") if f.is_file())
    assert size < 10 * 1024 * 1024
    assert {p.parent.name for p in BAGS} == {"U10DD", "EC60", "T2822", "U10GB"}


def test_eval_reproduces_the_stored_figures() -> None:
    stored = json.loads((ROOT / "bags" / "eval.json").read_text())["trials"]
    fresh = {Path(r.bag).relative_to(ROOT).as_posix(): r.as_dict() for r in evaluate(BAGS)}
    assert len(fresh) == len(stored) == len(BAGS)
    for row in stored:
        now = fresh[row["bag"]]
        for key, value in row.items():
            if isinstance(value, float):
                assert now[key] == pytest.approx(value, rel=1e-9, abs=1e-12), (row["bag"], key)
            elif key != "bag":
                assert now[key] == value, (row["bag"], key)


@pytest.mark.parametrize("bag", BAGS, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_the_offline_estimator_gives_the_recorded_onset(bag: Path) -> None:
    """What `transparency eval` uses for a bag without /contact: the node's core, replayed."""
    with open_bag(bag) as source:
        custom = source.custom_data
        recorded = [stamp_to_ns(m.header.stamp) for _, _, m in source.messages(["/contact"])]
        onset = offline_onset(
            source, float(custom["transparency.k_s"]), float(custom["transparency.threshold_rad"])
        )
    if not recorded:
        assert onset is None
        return
    assert onset is not None
    assert onset[0] == recorded[0]  # the same sample's stamp, to the nanosecond


@pytest.mark.parametrize("bag", BAGS, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_replayed_bag_gives_the_recorded_onset(bag: Path, ros_context: Context) -> None:
    with open_bag(bag) as source:
        custom = source.custom_data
        recorded = [stamp_to_ns(m.header.stamp) for _, _, m in source.messages(["/contact"])]
        samples = joint_series(source, "/joint_states").stamp_ns
        # theta_d of the trial (the estimator had it before the recording started)
        theta_d = float(joint_series(source, "/joint_commands").position[-1])
    estimator = ContactEstimatorNode(
        context=ros_context,
        parameter_overrides=[
            Parameter("k_s", value=float(custom["transparency.k_s"])),
            Parameter("theta_d_rad", value=theta_d),
            Parameter("contact_onset_rad", value=float(custom["transparency.threshold_rad"])),
            Parameter("contact_release_rad", value=float(custom["transparency.threshold_rad"]) / 2),
        ],
    )
    probe = Node("replay_probe", context=ros_context)
    onsets: list[int] = []
    probe.create_subscription(
        WrenchStamped, "/contact", lambda m: onsets.append(stamp_to_ns(m.header.stamp)), 100
    )
    spinner = Spinner(ros_context, estimator, probe)
    try:
        replay = subprocess.run(
            [str(Path(sys.executable).parent / "bag_replay"), str(bag), "--rate", "0.25",
             "--topics", "/joint_commands", "/joint_states", "--delay", "0.2",
             "--wait-for-subscribers", "1"],
            capture_output=True, text=True, timeout=60, check=False,
        )  # fmt: skip
        assert replay.returncode == 0, replay.stderr
        assert "published" in replay.stderr
        if not recorded:
            assert not wait_for(lambda: bool(onsets), 0.5)
            return
        assert wait_for(lambda: bool(onsets), 5.0)
        # the same sample, or its neighbour if a sample was lost in transport; either way the
        # onset carries the stamp of a recorded sample, exactly
        assert onsets[0] in set(samples.tolist())
        index = np.searchsorted(samples, recorded[0])
        got = np.searchsorted(samples, onsets[0])
        assert abs(int(got) - int(index)) <= 1, onsets[0] - recorded[0]
    finally:
        spinner.stop()
        estimator.destroy_node()
        probe.destroy_node()
