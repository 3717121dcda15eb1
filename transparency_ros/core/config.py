"""Typed, validated configuration: Table 1 actuators and the drop-test settings.

Values carry their unit in their name. Every loader checks types, ranges and the relations the
paper states between quantities, and reports the file and key path of anything wrong.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from fractions import Fraction
from functools import lru_cache
from pathlib import Path
from typing import Any

import yaml

from transparency_ros.core.errors import ConfigError, UnknownActuatorError
from transparency_ros.core.resources import config_file

SCHEMA_VERSION = 1

# Relative tolerances for the relations of Table 1 (the printed values are rounded).
KM_PER_MASS_RTOL = 0.05  # the paper's T2822 value is 4 % off its own k_m / m
POWER_RTOL = 0.02  # P_c = 1/4 tau_c v_n


# Field metadata read by _parse_fields: how to parse a value and which range it must lie in.
_POSITIVE: Mapping[str, Any] = {"min": 0.0, "inclusive": False}
_NON_NEGATIVE: Mapping[str, Any] = {"min": 0.0, "inclusive": True}


@dataclass(frozen=True)
class ActuatorParams:
    """One column of Table 1. All values output-referred (after the gearbox)."""

    name: str = field(metadata={"kind": "name"})
    description: str = field(metadata={"kind": "text"})
    reduction: Fraction = field(metadata={"kind": "ratio"})
    backlash_deg: float = field(metadata=_NON_NEGATIVE)
    mass_kg: float = field(metadata=_POSITIVE)
    max_continuous_torque_nm: float = field(metadata=_POSITIVE)
    motor_constant_nm_per_sqrt_w: float = field(metadata=_POSITIVE)
    km_per_mass_nm_per_sqrt_w_kg: float = field(metadata=_POSITIVE)
    nominal_speed_at_15v_rev_s: float = field(metadata=_POSITIVE)
    peak_torque_nm: float = field(metadata=_POSITIVE)
    peak_torque_exceeds_gearbox_rating: bool = field(metadata={"kind": "bool"})
    max_continuous_power_w: float = field(metadata=_POSITIVE)
    reflected_inertia_kgm2: float = field(metadata=_POSITIVE)
    static_friction_nm: float = field(metadata=_NON_NEGATIVE)
    coulomb_friction_nm: float = field(metadata=_NON_NEGATIVE)
    viscous_damping_nms_per_rad: float = field(metadata=_NON_NEGATIVE)

    @property
    def backlash_rad(self) -> float:
        return math.radians(self.backlash_deg)

    @property
    def reduction_ratio(self) -> float:
        return float(self.reduction)

    @property
    def nominal_speed_at_15v_rad_s(self) -> float:
        return self.nominal_speed_at_15v_rev_s * 2.0 * math.pi


@dataclass(frozen=True)
class DropTestConfig:
    """Settings of the drop-test experiment (Sec. 3.1) and contact-model defaults."""

    arm_length_m: float = field(metadata=_POSITIVE)
    arm_inertia_kgm2: float = field(metadata=_NON_NEGATIVE)
    k_s_nm_per_rad: float = field(metadata=_POSITIVE)
    k_d_nms_per_rad: float = field(metadata=_NON_NEGATIVE)
    threshold_rad: float = field(metadata=_POSITIVE)
    contact_force_threshold_n: float = field(metadata=_POSITIVE)
    drop_height_range_m: tuple[float, float] = field(metadata={"kind": "range"})
    shuttle_mass_kg: Mapping[str, float] = field(metadata={"kind": "per_actuator"})

    def shuttle_mass_for(self, actuator: str) -> float:
        try:
            return self.shuttle_mass_kg[actuator]
        except KeyError:
            known = ", ".join(sorted(self.shuttle_mass_kg))
            raise UnknownActuatorError(
                f"drop_test.shuttle_mass_kg has no entry for actuator {actuator!r} (has: {known})"
            ) from None


# --------------------------------------------------------------------------- parsing helpers


def finite_number(value: Any, where: str) -> float:
    """A YAML value that must be a finite number (not a bool, not text); ConfigError otherwise."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(f"{where}: expected a number, got {value!r}")
    number = float(value)
    if not math.isfinite(number):
        raise ConfigError(f"{where}: must be finite, got {value!r}")
    return number


def _check_range(number: float, meta: Mapping[str, Any], where: str) -> None:
    low = meta.get("min")
    if low is None:
        return
    if meta.get("inclusive", True):
        if number < low:
            raise ConfigError(f"{where}: must be >= {low:g}, got {number:g}")
    elif number <= low:
        raise ConfigError(f"{where}: must be > {low:g}, got {number:g}")


def _ratio(value: Any, where: str) -> Fraction:
    try:
        if isinstance(value, str):
            ratio = Fraction(value.replace(" ", ""))
        else:
            ratio = Fraction(str(finite_number(value, where)))
    except (ValueError, ZeroDivisionError) as err:
        raise ConfigError(f"{where}: expected a number or a fraction 'a/b', got {value!r}") from err
    if ratio <= 0:
        raise ConfigError(f"{where}: must be > 0, got {value!r}")
    return ratio


def _parse_text(value: Any, where: str, _meta: Mapping[str, Any]) -> str:
    if not isinstance(value, str):
        raise ConfigError(f"{where}: expected text, got {value!r}")
    return value


def _parse_bool(value: Any, where: str, _meta: Mapping[str, Any]) -> bool:
    if not isinstance(value, bool):
        raise ConfigError(f"{where}: expected true or false, got {value!r}")
    return value


def _parse_range(value: Any, where: str, _meta: Mapping[str, Any]) -> tuple[float, float]:
    if not isinstance(value, (list, tuple)) or len(value) != 2:
        raise ConfigError(f"{where}: expected [low, high], got {value!r}")
    low, high = (finite_number(v, f"{where}[{i}]") for i, v in enumerate(value))
    if not 0 < low < high:
        raise ConfigError(f"{where}: expected 0 < low < high, got {value!r}")
    return (low, high)


def _parse_per_actuator(value: Any, where: str, _meta: Mapping[str, Any]) -> dict[str, float]:
    if not isinstance(value, Mapping) or not value:
        raise ConfigError(f"{where}: expected a non-empty mapping actuator -> value")
    per: dict[str, float] = {}
    for name, item in value.items():
        per[str(name)] = _parse_number(item, f"{where}.{name}", {"min": 0.0, "inclusive": False})
    return per


def _parse_number(value: Any, where: str, meta: Mapping[str, Any]) -> float:
    number = finite_number(value, where)
    _check_range(number, meta, where)
    return number


_PARSERS: dict[str, Any] = {
    "text": _parse_text,
    "bool": _parse_bool,
    "ratio": lambda value, where, _meta: _ratio(value, where),
    "range": _parse_range,
    "per_actuator": _parse_per_actuator,
    "number": _parse_number,
}


def _parse_fields(cls: type, raw: Any, where: str, extra: Mapping[str, Any]) -> dict[str, Any]:
    """Convert a YAML mapping into constructor arguments of dataclass ``cls``.

    Each field's ``metadata["kind"]`` picks its parser (default: a finite number, range-checked
    by ``metadata["min"]``/``["inclusive"]``); ``extra`` supplies fields not read from YAML.
    """
    if not isinstance(raw, Mapping):
        raise ConfigError(f"{where}: expected a mapping, got {type(raw).__name__}")
    given = dict(raw)
    known = {f.name for f in fields(cls)} - set(extra)
    unknown = sorted(set(given) - known)
    if unknown:
        raise ConfigError(f"{where}: unknown key(s) {unknown}; allowed: {sorted(known)}")
    missing = sorted(known - set(given))
    if missing:
        raise ConfigError(f"{where}: missing key(s) {missing}")
    out: dict[str, Any] = dict(extra)
    for f in fields(cls):
        if f.name not in extra:
            parser = _PARSERS[f.metadata.get("kind", "number")]
            out[f.name] = parser(given[f.name], f"{where}.{f.name}", f.metadata)
    return out


def _check_actuator_relations(a: ActuatorParams, where: str) -> None:
    if a.static_friction_nm < a.coulomb_friction_nm:
        raise ConfigError(
            f"{where}: static_friction_nm ({a.static_friction_nm}) must be >= "
            f"coulomb_friction_nm ({a.coulomb_friction_nm})"
        )
    if a.peak_torque_nm < a.max_continuous_torque_nm:
        raise ConfigError(
            f"{where}: peak_torque_nm ({a.peak_torque_nm}) must be >= "
            f"max_continuous_torque_nm ({a.max_continuous_torque_nm})"
        )
    km_per_mass = a.motor_constant_nm_per_sqrt_w / a.mass_kg
    if abs(a.km_per_mass_nm_per_sqrt_w_kg - km_per_mass) > KM_PER_MASS_RTOL * km_per_mass:
        raise ConfigError(
            f"{where}.km_per_mass_nm_per_sqrt_w_kg: {a.km_per_mass_nm_per_sqrt_w_kg} disagrees "
            f"with motor_constant/mass = {km_per_mass:.4g} by more than {KM_PER_MASS_RTOL:.0%}"
        )
    power = 0.25 * a.max_continuous_torque_nm * a.nominal_speed_at_15v_rad_s
    if abs(a.max_continuous_power_w - power) > POWER_RTOL * power:
        raise ConfigError(
            f"{where}.max_continuous_power_w: {a.max_continuous_power_w} disagrees with "
            f"1/4 tau_c v_n = {power:.4g} W by more than {POWER_RTOL:.0%}"
        )


def _read_yaml(path: Path) -> Mapping[str, Any]:
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as err:
        raise ConfigError(f"{path}: cannot read: {err.strerror or err}") from err
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as err:
        raise ConfigError(f"{path}: not valid YAML: {err}") from err
    if not isinstance(data, Mapping):
        raise ConfigError(f"{path}: expected a mapping at the top level")
    version = data.get("schema_version")
    if version != SCHEMA_VERSION:
        raise ConfigError(f"{path}: schema_version must be {SCHEMA_VERSION}, got {version!r}")
    return data


# --------------------------------------------------------------------------- public loaders


def parse_actuators(data: Mapping[str, Any], source: str) -> dict[str, ActuatorParams]:
    """Validate the ``actuators`` section of an already-parsed YAML document."""
    section = data.get("actuators")
    if not isinstance(section, Mapping) or not section:
        raise ConfigError(f"{source}: 'actuators' must be a non-empty mapping")
    unexpected = sorted(set(data) - {"schema_version", "actuators"})
    if unexpected:
        raise ConfigError(f"{source}: unknown top-level key(s) {unexpected}")
    result: dict[str, ActuatorParams] = {}
    for name, raw in section.items():
        where = f"{source}: actuators.{name}"
        params = ActuatorParams(**_parse_fields(ActuatorParams, raw, where, {"name": str(name)}))
        _check_actuator_relations(params, where)
        result[str(name)] = params
    return result


def parse_drop_test(data: Mapping[str, Any], source: str) -> DropTestConfig:
    """Validate an already-parsed drop-test YAML document."""
    body = {k: v for k, v in data.items() if k != "schema_version"}
    return DropTestConfig(**_parse_fields(DropTestConfig, body, source, {}))


@lru_cache(maxsize=8)
def _load_actuators_cached(path: Path) -> dict[str, ActuatorParams]:
    return parse_actuators(_read_yaml(path), str(path))


@lru_cache(maxsize=8)
def _load_drop_test_cached(path: Path) -> DropTestConfig:
    return parse_drop_test(_read_yaml(path), str(path))


def load_actuators(path: str | Path | None = None) -> dict[str, ActuatorParams]:
    """All actuators of ``actuators.yaml`` (the installed one unless ``path`` is given)."""
    resolved = Path(path) if path is not None else config_file("actuators.yaml")
    return dict(_load_actuators_cached(resolved.resolve()))


def get_actuator(name: str, path: str | Path | None = None) -> ActuatorParams:
    """One actuator by its Table 1 name (``U10DD``, ``EC60``, ``T2822``, ``U10GB``)."""
    actuators = load_actuators(path)
    try:
        return actuators[name]
    except KeyError:
        known = ", ".join(actuators)
        raise UnknownActuatorError(f"unknown actuator {name!r}; known: {known}") from None


def load_drop_test(path: str | Path | None = None) -> DropTestConfig:
    """The drop-test settings of ``drop_test.yaml`` (the installed one unless ``path`` is given)."""
    resolved = Path(path) if path is not None else config_file("drop_test.yaml")
    return _load_drop_test_cached(resolved.resolve())
