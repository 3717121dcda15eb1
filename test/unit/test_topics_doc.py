"""docs/topics.md lists every topic the nodes create (a new topic without its QoS documented
fails here)."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
CREATES = re.compile(
    r"(?:create_publisher|create_lifecycle_publisher|create_subscription|hot_path\.subscribe)"
    r"\(\s*\w+,\s*f?\"([^\"]+)\""
)


def test_every_topic_the_nodes_create_is_documented_with_its_qos() -> None:
    table = (ROOT / "docs" / "topics.md").read_text(encoding="utf-8")
    sources = [*(ROOT / "transparency_ros" / "ros").glob("*.py"),
               *(ROOT / "transparency_ros" / "ros" / "actuator_driver").glob("*.py")]  # fmt: skip
    nodes = ("feel_cage_behavior", "contact_estimator", "actuator_driver", "sim_ball", "sim_rig")
    topics = {
        name.replace("{event.joint}", "<joint>")
        for path in sources if path.stem in nodes or path.parent.name == "actuator_driver"
        for name in CREATES.findall(path.read_text(encoding="utf-8"))
    }  # fmt: skip
    assert {"/joint_states", "/joint_setpoints", "/contact", "~/state/<joint>"} <= topics
    missing = [t for t in sorted(topics) if f"`{t}`" not in table]
    assert not missing, f"not in docs/topics.md: {missing}"
