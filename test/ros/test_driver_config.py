"""config/actuator_driver.yaml lists exactly the node's parameters with their defaults (the docs'
generated parts are checked in test_docs.py)."""

from __future__ import annotations

import pytest
import yaml

pytest.importorskip("rclpy")
from transparency_ros.core.resources import config_file
from transparency_ros.ros.actuator_driver import PARAMETERS


def test_params_file_matches_the_parameter_table() -> None:
    data = yaml.safe_load(config_file("actuator_driver.yaml").read_text())
    params = data["actuator_driver"]["ros__parameters"]
    assert params == {spec.name: spec.default for spec in PARAMETERS}


def test_every_parameter_has_a_description_and_runtime_ones_a_range_or_choices() -> None:
    for spec in PARAMETERS:
        assert spec.description, spec.name
        if not spec.read_only and isinstance(spec.default, (int, float)):
            bounded = spec.low is not None or spec.name.startswith("position_")
            assert bounded, f"{spec.name} is changeable at runtime but has no range"
