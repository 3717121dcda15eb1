"""config/actuators.yaml and config/drop_test.yaml: Table 1 loaded into validated objects."""

from __future__ import annotations

import math
from fractions import Fraction
from pathlib import Path
from typing import Any

import pytest
import yaml

from transparency_ros.core import resources
from transparency_ros.core.config import get_actuator, load_actuators, load_drop_test
from transparency_ros.core.errors import ConfigError, UnknownActuatorError

# Table 1 of the paper, transcribed independently of config/actuators.yaml:
# reduction, backlash deg, mass kg, tau_c, k_m, v_n rev/s, tau_p, P_c W, J_r, tau_s, tau_coul, b_v
TABLE_1 = {
    "U10DD": (
        Fraction(1),
        0.0,
        0.405,
        2.36,
        0.285,
        25.00,
        8.05,
        92.60,
        4.47e-4,
        0.075,
        0.032,
        0.099,
    ),
    "EC60": (
        Fraction(13, 3),
        0.6,
        0.730,
        1.21,
        0.370,
        18.06,
        12.35,
        34.29,
        2.27e-3,
        0.061,
        0.026,
        0.153,
    ),
    "T2822": (
        Fraction(17576, 343),
        1.0,
        0.251,
        2.12,
        0.617,
        8.99,
        11.44,
        29.96,
        3.02e-3,
        0.222,
        0.114,
        0.835,
    ),
    "U10GB": (
        Fraction(13, 3),
        0.6,
        0.865,
        10.22,
        1.236,
        5.77,
        35.3,
        92.60,
        8.39e-3,
        0.347,
        0.253,
        1.890,
    ),
}
FIELDS = (
    "reduction",
    "backlash_deg",
    "mass_kg",
    "max_continuous_torque_nm",
    "motor_constant_nm_per_sqrt_w",
    "nominal_speed_at_15v_rev_s",
    "peak_torque_nm",
    "max_continuous_power_w",
    "reflected_inertia_kgm2",
    "static_friction_nm",
    "coulomb_friction_nm",
    "viscous_damping_nms_per_rad",
)


@pytest.mark.parametrize("name", list(TABLE_1))
def test_installed_table_matches_the_paper(name: str) -> None:
    actuator = get_actuator(name)
    for field_name, expected in zip(FIELDS, TABLE_1[name], strict=True):
        assert getattr(actuator, field_name) == expected, field_name
    assert actuator.name == name


def test_all_four_actuators_in_table_order() -> None:
    assert list(load_actuators()) == ["U10DD", "EC60", "T2822", "U10GB"]


def test_derived_units() -> None:
    t2822 = get_actuator("T2822")
    assert t2822.reduction_ratio == pytest.approx(51.2420, abs=1e-4)
    assert t2822.backlash_rad == pytest.approx(math.pi / 180)
    assert get_actuator("U10DD").nominal_speed_at_15v_rad_s == pytest.approx(50 * math.pi)
    assert get_actuator("EC60").peak_torque_exceeds_gearbox_rating
    assert not get_actuator("T2822").peak_torque_exceeds_gearbox_rating


def test_unknown_actuator_names_the_known_ones() -> None:
    with pytest.raises(UnknownActuatorError, match=r"'U10XX'.*U10DD, EC60, T2822, U10GB"):
        get_actuator("U10XX")
    assert issubclass(UnknownActuatorError, LookupError)
    assert issubclass(UnknownActuatorError, ValueError)


def test_drop_test_settings() -> None:
    d = load_drop_test()
    assert d.arm_length_m == 0.1
    assert d.k_s_nm_per_rad == 2.0
    assert d.k_d_nms_per_rad == 0.0
    assert d.threshold_rad == 0.1
    assert d.drop_height_range_m == (0.03, 1.1)
    assert [d.shuttle_mass_for(n) for n in TABLE_1] == [0.54, 0.54, 0.71, 0.71]
    with pytest.raises(UnknownActuatorError, match=r"shuttle_mass_kg.*'AK80'"):
        d.shuttle_mass_for("AK80")


# ------------------------------------------------------------------ bad files: clear errors


def _actuators_doc() -> dict[str, Any]:
    data = yaml.safe_load(resources.config_file("actuators.yaml").read_text())
    assert isinstance(data, dict)
    return data


def _write(tmp_path: Path, data: Any, name: str = "actuators.yaml") -> Path:
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.mark.parametrize(
    ("key", "value", "message"),
    [
        ("mass_kg", -0.4, r"actuators\.EC60\.mass_kg: must be > 0, got -0.4"),
        ("mass_kg", "heavy", r"actuators\.EC60\.mass_kg: expected a number, got 'heavy'"),
        ("mass_kg", True, r"actuators\.EC60\.mass_kg: expected a number"),
        ("reflected_inertia_kgm2", float("nan"), r"reflected_inertia_kgm2: must be finite"),
        ("reflected_inertia_kgm2", 0.0, r"reflected_inertia_kgm2: must be > 0"),
        ("backlash_deg", -1.0, r"backlash_deg: must be >= 0"),
        ("reduction", "13/0", r"reduction: expected a number or a fraction"),
        ("reduction", "-13/3", r"reduction: must be > 0"),
        ("static_friction_nm", 0.01, r"static_friction_nm \(0.01\) must be >= coulomb"),
        ("peak_torque_nm", 1.0, r"peak_torque_nm \(1.0\) must be >= max_continuous"),
        ("km_per_mass_nm_per_sqrt_w_kg", 0.9, r"km_per_mass.*disagrees with motor_constant/mass"),
        ("max_continuous_power_w", 50.0, r"max_continuous_power_w.*disagrees with 1/4 tau_c v_n"),
        ("peak_torque_exceeds_gearbox_rating", "yes", r"expected true or false, got 'yes'"),
        ("description", 42, r"description: expected text"),
    ],
)
def test_bad_value_names_file_and_key(tmp_path: Path, key: str, value: Any, message: str) -> None:
    data = _actuators_doc()
    data["actuators"]["EC60"][key] = value
    path = _write(tmp_path, data)
    with pytest.raises(ConfigError, match=message) as info:
        load_actuators(path)
    assert str(path) in str(info.value)


def test_missing_and_unknown_keys(tmp_path: Path) -> None:
    data = _actuators_doc()
    del data["actuators"]["T2822"]["coulomb_friction_nm"]
    with pytest.raises(
        ConfigError, match=r"actuators\.T2822: missing key\(s\) \['coulomb_friction_nm'\]"
    ):
        load_actuators(_write(tmp_path, data))
    data = _actuators_doc()
    data["actuators"]["T2822"]["colour"] = "red"
    with pytest.raises(ConfigError, match=r"unknown key\(s\) \['colour'\]"):
        load_actuators(_write(tmp_path, data, "b.yaml"))


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("actuators: [1, 2", "not valid YAML"),
        ("- 1\n- 2\n", "expected a mapping at the top level"),
        ("actuators: {}\n", "schema_version must be 1, got None"),
        ("schema_version: 1\nactuators: {}\n", "'actuators' must be a non-empty mapping"),
        ("schema_version: 1\nactuators: {A: 3}\n", r"actuators\.A: expected a mapping"),
    ],
)
def test_malformed_documents(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "actuators.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=message):
        load_actuators(path)


def test_unreadable_file(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="cannot read"):
        load_actuators(tmp_path / "nope.yaml")


def test_bad_drop_test(tmp_path: Path) -> None:
    data = yaml.safe_load(resources.config_file("drop_test.yaml").read_text())
    data["drop_height_range_m"] = [1.1, 0.03]
    with pytest.raises(ConfigError, match=r"drop_height_range_m: expected 0 < low < high"):
        load_drop_test(_write(tmp_path, data, "d1.yaml"))
    data["drop_height_range_m"] = [0.03, 1.1]
    data["shuttle_mass_kg"]["U10DD"] = 0
    with pytest.raises(ConfigError, match=r"shuttle_mass_kg\.U10DD: must be > 0"):
        load_drop_test(_write(tmp_path, data, "d2.yaml"))


def test_config_dir_override_and_search_report(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    data = _actuators_doc()
    data["actuators"] = {"U10DD": data["actuators"]["U10DD"]}
    _write(tmp_path, data)
    monkeypatch.setenv("TRANSPARENCY_CONFIG_DIR", str(tmp_path))
    assert resources.config_file("actuators.yaml") == tmp_path / "actuators.yaml"
    assert list(load_actuators()) == ["U10DD"]
    with pytest.raises(ConfigError, match=rf"'missing\.yaml' not found; searched: {tmp_path}"):
        resources.config_file("missing.yaml")
