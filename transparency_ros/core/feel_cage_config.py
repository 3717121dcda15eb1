"""The feel-cage task's configuration (config/feel_cage.yaml): geometry, balls, task settings.

Shared by the nodes (the simulated actuator's ball on the rail, the behavior's defaults) and the
Table 2 analysis, so it lives in the core rather than in either of them.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from transparency_ros.core.ball_on_rail import Ball, RailGeometry
from transparency_ros.core.config import finite_number
from transparency_ros.core.errors import ConfigError, ModelError
from transparency_ros.core.resources import config_file


@dataclass(frozen=True)
class FeelCageSetup:
    geometry: RailGeometry
    balls: dict[str, Ball]
    k_s_nm_per_rad: float = 2.0
    epsilon_nm: float = 0.02
    sample_rate_hz: float = 1000.0
    process_time_s: float = 0.001
    act_voltage_v: float = 10.5
    friction_ripple: float = 0.0  # position-dependent friction, see PhysicsParams
    settle_s: float = 6.0  # steady sweep before e_s is measured
    start_before_contact_rad: float = 0.3
    after_cage_s: float = 1.0  # keep simulating the ball to find when it would have left

    @property
    def epsilon_rad(self) -> float:
        return self.epsilon_nm / self.k_s_nm_per_rad


def load_setup(path: str | Path | None = None) -> FeelCageSetup:
    """The installed config/feel_cage.yaml unless ``path`` is given; errors name file and key."""
    source = Path(path) if path else config_file("feel_cage.yaml")
    try:
        data: dict[str, Any] = yaml.safe_load(source.read_text(encoding="utf-8"))
        geometry = RailGeometry(**_numbers(data["geometry"], f"{source}: geometry"))
        balls = {
            name: Ball(name=name, **_numbers(values, f"{source}: balls.{name}"))
            for name, values in data["balls"].items()
        }
        task = _numbers(data.get("task", {}), f"{source}: task")
        return FeelCageSetup(geometry, balls, **task)
    except (OSError, yaml.YAMLError, KeyError, TypeError, ModelError) as err:
        raise ConfigError(f"{source}: {err}") from err


def _numbers(section: dict[str, Any], where: str) -> dict[str, float]:
    return {key: finite_number(value, f"{where}.{key}") for key, value in section.items()}
