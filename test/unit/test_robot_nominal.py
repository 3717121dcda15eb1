"""``--nominal`` for a robot: the URDF's terms overridden from a generic file or the DFKI
double pendulum's parameter file (checked against the lab's published equations)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from transparency_ros.analysis.robot_nominal import with_nominal
from transparency_ros.core.errors import ConfigError
from transparency_ros.core.robot_calibration import effort_limit
from transparency_ros.core.robot_model import RobotModel
from transparency_ros.synth.robots import chain_urdf

SHARED = Path(__file__).resolve().parents[1] / "data" / "double_pendulum"  # the lab's files
LAB = {"I1": 0.031887199591513114, "I2": 0.05086984812807257, "Ir": 6.287203962819607e-05,
       "m1": 0.5234602302310271, "m2": 0.6255677234174437, "l1": 0.2, "r1": 0.2,
       "r2": 0.25569305436052964, "gr": 6.0, "g": 9.81}  # fmt: skip


def lab_mass_matrix(q: np.ndarray) -> np.ndarray:
    """The lab's M(q) (the data's README), with its rotor terms."""
    c2 = math.cos(q[1])
    i1, i2, ir, m2, l1, r2, gr = (LAB[k] for k in ("I1", "I2", "Ir", "m2", "l1", "r2", "gr"))
    m00 = i1 + i2 + m2 * l1**2 + 2 * m2 * l1 * r2 * c2 + gr**2 * ir + ir
    m01 = i2 + m2 * l1 * r2 * c2 - gr * ir
    return np.array([[m00, m01], [m01, i2 + gr**2 * ir]])


def test_the_labs_parameter_file_gives_the_labs_equations_on_its_urdf() -> None:
    """The URDF's mass matrix is about 35 % off the lab's (its inertias about the wrong point);
    with the lab's file it is the lab's to the rotor's terms off the diagonal (left out, with
    a note: 4e-4 kg m^2 here), gravity unchanged (it agreed), friction at cf pi/2."""
    urdf = RobotModel.from_urdf(SHARED / "pendubot.urdf")
    lab = with_nominal(urdf, SHARED / "model_parameters.yml")
    for q in (np.array([0.3, 0.5]), np.array([1.0, -0.4]), np.array([2.5, 1.2])):
        assert np.abs(urdf.mass_matrix(q) - lab_mass_matrix(q)).max() > 0.05
        assert np.abs(lab.mass_matrix(q) - lab_mass_matrix(q)).max() < 5e-4
        assert lab.gravity(q) == pytest.approx(urdf.gravity(q), abs=1e-6)
    assert lab.friction.coulomb.tolist() == pytest.approx([0.16 * math.pi / 2, 0.12 * math.pi / 2])
    assert lab.friction.viscous.tolist() == pytest.approx([0.001, 0.001])
    assert effort_limit(lab).tolist() == [10.0, 10.0]
    assert any("left out" in n for n in lab.notes) and any("pi/2" in n for n in lab.notes)
    assert lab.source.endswith("+ model_parameters.yml")


def test_a_generic_file_overrides_the_terms_it_names_and_only_those(tmp_path: Path) -> None:
    urdf = RobotModel.from_urdf(chain_urdf(2))
    spec = tmp_path / "nominal.yaml"
    spec.write_text(
        "gravity_mps2: 9.0\n"
        "joints:\n  j1: {armature_kgm2: 0.01, coulomb_nm: 0.3, effort_limit_nm: 7}\n"
        "links:\n  l0: {mass_kg: 0.9, com_m: [0, 0, -0.12]}\n"
    )
    model = with_nominal(urdf, spec)
    pm = model.pin_model
    assert pm.inertias[1].mass == pytest.approx(0.9)
    assert np.array(pm.inertias[1].lever).tolist() == pytest.approx([0, 0, -0.12])
    assert np.array(pm.inertias[2].inertia) == pytest.approx(
        np.array(urdf.pin_model.inertias[2].inertia)
    )
    assert pm.armature.tolist() == [0.0, 0.01]
    assert model.friction.coulomb.tolist() == pytest.approx([0.05, 0.3])
    assert model.friction.viscous.tolist() == pytest.approx(urdf.friction.viscous.tolist())
    assert effort_limit(model).tolist() == [20.0, 7.0]
    assert np.array(pm.gravity.linear).tolist() == pytest.approx([0, 0, -9.0])
    assert urdf.pin_model.armature.tolist() == [0.0, 0.0]  # the URDF's model is left alone


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("mass: 1\n", r"unknown terms \['mass'\]"),
        ("joints:\n  j7: {coulomb_nm: 0.1}\n", "joint 'j7' is not a movable joint"),
        ("joints:\n  j0: {coulomb: 0.1}\n", r"joints: j0: unknown terms \['coulomb'\]"),
        ("links:\n  arm: {mass_kg: 1}\n", "link 'arm' is not moved by a joint"),
        ("links:\n  l0: {com_m: [0, 1]}\n", "links: l0: com_m: a list of 3 numbers"),
        ("links:\n  l0: {mass_kg: -1}\n", "mass_kg -1.0 is negative"),
        ("joints:\n  j0: {coulomb_nm: .nan}\n", "j0: coulomb_nm"),
        ("m1: 1\nm2: 1\nr1: 0.1\n", r"lacks \['r2', 'I1', 'I2'\]"),
    ],
)
def test_a_bad_nominal_file_is_refused_naming_what_and_where(
    tmp_path: Path, text: str, message: str
) -> None:
    spec = tmp_path / "bad.yaml"
    spec.write_text(text)
    with pytest.raises(ConfigError, match=message):
        with_nominal(RobotModel.from_urdf(chain_urdf(2)), spec)


def test_the_labs_file_needs_no_lengths_and_notes_one_the_urdf_disagrees_with(
    tmp_path: Path,
) -> None:
    urdf = RobotModel.from_urdf(SHARED / "pendubot.urdf")
    text = (SHARED / "model_parameters.yml").read_text()
    without = tmp_path / "no_lengths.yml"
    without.write_text("".join(x + "\n" for x in text.splitlines() if not x.startswith("l")))
    same = with_nominal(urdf, SHARED / "model_parameters.yml")
    q = np.array([0.3, 0.5])
    assert with_nominal(urdf, without).mass_matrix(q) == pytest.approx(same.mass_matrix(q))
    assert not any("l1" in n for n in same.notes)  # 0.2 m, as the URDF has it
    longer = tmp_path / "longer.yml"
    longer.write_text(text.replace("l1: 0.2", "l1: 0.3"))
    assert any(
        "l1 0.3 m, the URDF's joint 2 is 0.2 m" in n for n in with_nominal(urdf, longer).notes
    )


def test_the_labs_file_is_refused_for_a_robot_of_three_joints() -> None:
    with pytest.raises(ConfigError, match="has 3 movable joints"):
        with_nominal(RobotModel.from_urdf(chain_urdf(3)), SHARED / "model_parameters.yml")


def test_the_discrepancy_tool_starts_from_the_nominal_model(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """The lab's own model fits its robot better than the URDF does: with --nominal the
    held-out residual before any effect is lower on both joints."""
    from transparency_ros.cli import main  # noqa: PLC0415

    runs = [str(SHARED / f"pendubot_clean_0{k}.csv.xz") for k in (1, 2)]
    common = ["discrepancy", *runs, "--urdf", str(SHARED / "pendubot.urdf"), "--json"]
    assert main(common) == 0
    urdf = json.loads(capsys.readouterr().out)["heldout_rms_nm"]
    assert main([*common, "--nominal", str(SHARED / "model_parameters.yml")]) == 0
    out = capsys.readouterr()
    lab = json.loads(out.out)["heldout_rms_nm"]
    assert "note: model_parameters.yml: the rotor's inertia" in out.err
    for joint in ("Joint1", "Joint2"):
        assert lab[joint][0] < urdf[joint][0]


def test_the_assay_starts_from_the_nominal_model_too(capsys: pytest.CaptureFixture[str]) -> None:
    """The textbook observer on the lab's model needs a lower threshold than on the URDF."""
    from transparency_ros.cli import main  # noqa: PLC0415

    runs = [str(SHARED / f"pendubot_clean_0{k}.csv.xz") for k in (1, 2)]
    common = ["assay", *runs, "--urdf", str(SHARED / "pendubot.urdf"), "--folds", "2",
              "--placements", "1", "--detectors", "textbook", "--json"]  # fmt: skip
    assert main(common) == 0
    urdf = json.loads(capsys.readouterr().out)["detectors"]["textbook"]
    assert main([*common, "--nominal", str(SHARED / "model_parameters.yml")]) == 0
    out = capsys.readouterr()
    lab = json.loads(out.out)["detectors"]["textbook"]
    assert "note: model_parameters.yml: the rotor's inertia" in out.err
    for a, b in zip(lab, urdf, strict=True):
        assert a["threshold_nm"] < b["threshold_nm"]
