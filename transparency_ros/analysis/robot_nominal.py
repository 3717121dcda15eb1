"""``--nominal`` for a robot: terms of its URDF's model overridden from a file.

Two formats. The generic one names what it changes, in SI units (every key checked; a joint or
link the URDF lacks is refused by name)::

    gravity_mps2: 9.81
    joints:
      Joint1: {armature_kgm2: 0.0023, viscous_nms_per_rad: 0.001, coulomb_nm: 0.25,
               effort_limit_nm: 10}
    links:
      Link2: {mass_kg: 0.63, com_m: [0, 0, 0.256], inertia_com_kgm2: [ixx, ixy, iyy, ixz, iyz, izz]}

(the inertia about the centre of mass, in the link's frame, as a URDF writes it). The other is
the DFKI Underactuated Lab's double-pendulum parameter file (``m1 m2 l1 l2 r1 r2 I1 I2 Ir gr b1
b2 cf1 cf2 g tl1 tl2``; their equations in ../shared/external/double_pendulum/README.md), for a
URDF of two movable joints: link i gets the mass m_i, its centre of mass r_i from the joint
across the axis in the direction the URDF puts it, its inertia about the joint axis I_i (the
URDF's other axes kept), the joint the rotor's inertia gr^2 Ir as armature, viscous b_i,
Coulomb friction cf_i pi/2 (their law cf atan(100 q') levels off there; ours is tanh(q' / eps))
and the effort limit tl_i. Their rotor terms off the diagonal (Ir in M00, -gr Ir in M01, below
1 % of the mass matrix on their robot) have no place in a URDF and are left out, with a note.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from transparency_ros.analysis.discrepancy.model import read_spec
from transparency_ros.core.config import finite_number
from transparency_ros.core.errors import ConfigError
from transparency_ros.core.robot_model import JointFriction, RobotModel

JOINT_TERMS = ("armature_kgm2", "viscous_nms_per_rad", "coulomb_nm", "effort_limit_nm")
LINK_TERMS = ("mass_kg", "com_m", "inertia_com_kgm2")
TOP_TERMS = ("gravity_mps2", "joints", "links")
DFKI_TERMS = ("m1", "m2", "l1", "l2", "r1", "r2", "I1", "I2", "Ir", "gr", "b1", "b2", "cf1",
              "cf2", "g", "tl1", "tl2")  # fmt: skip
DFKI_REQUIRED = ("m1", "m2", "r1", "r2", "I1", "I2")


def with_nominal(model: RobotModel, path: str | Path) -> RobotModel:
    """``model`` with the terms of the file at ``path`` (either format) in place of its own."""
    p = Path(path)
    data = read_spec(p)
    if "m1" in data:
        return _dfki(model, data, p)
    unknown = sorted(set(data) - set(TOP_TERMS))
    if unknown:
        raise ConfigError(
            f"{p}: unknown terms {unknown}; known: {list(TOP_TERMS)} (or the DFKI double "
            "pendulum's parameter file, m1 m2 l1 ...)"
        )
    import pinocchio as pin  # noqa: PLC0415

    pm = pin.Model(model.pin_model)
    friction = [model.friction.viscous.copy(), model.friction.coulomb.copy()]
    if "gravity_mps2" in data:
        g = finite_number(data["gravity_mps2"], f"{p}: gravity_mps2")
        pm.gravity.linear = np.array([0.0, 0.0, -g])
    for name, terms in _section(data, "joints", p).items():
        j = _joint(model, name, p)
        v = int(pm.joints[j + 1].idx_v)
        for key, value in _terms(terms, JOINT_TERMS, f"{p}: joints: {name}").items():
            number = finite_number(value, f"{p}: joints: {name}: {key}")
            if key == "armature_kgm2":
                pm.armature[v] = number
            elif key == "effort_limit_nm":
                pm.effortLimit[v] = number
            else:
                friction[0 if key == "viscous_nms_per_rad" else 1][j] = number
    for name, terms in _section(data, "links", p).items():
        j = _link(model, name, p)
        _set_link(pm, j, _terms(terms, LINK_TERMS, f"{p}: links: {name}"), f"{p}: links: {name}")
    joint_friction = JointFriction(friction[0], friction[1], model.friction.smoothing_rad_s)
    return RobotModel(pm, joint_friction, f"{model.source} + {p.name}", list(model.notes))


def _section(data: Mapping[str, Any], key: str, p: Path) -> dict[str, Any]:
    section = data.get(key, {})
    if not isinstance(section, dict):
        raise ConfigError(f"{p}: {key} is a mapping of names to terms")
    return section


def _terms(terms: Any, known: tuple[str, ...], where: str) -> dict[str, Any]:
    if not isinstance(terms, dict):
        raise ConfigError(f"{where}: a mapping of terms ({', '.join(known)})")
    unknown = sorted(set(terms) - set(known))
    if unknown:
        raise ConfigError(f"{where}: unknown terms {unknown}; known: {list(known)}")
    return terms


def _joint(model: RobotModel, name: str, p: Path) -> int:
    if name not in model.joint_names:
        raise ConfigError(
            f"{p}: joint {name!r} is not a movable joint of {model.source} "
            f"({list(model.joint_names)})"
        )
    return model.joint_names.index(name)


def _link(model: RobotModel, name: str, p: Path) -> int:
    """The index (into the movable joints) of the joint that moves link ``name``."""
    links = [model.child_link(j) for j in model.joint_names]
    if name not in links:
        raise ConfigError(
            f"{p}: link {name!r} is not moved by a joint of {model.source} (links: {links})"
        )
    return links.index(name)


def _vector(value: Any, size: int, where: str) -> np.ndarray:
    if not isinstance(value, list) or len(value) != size:
        raise ConfigError(f"{where}: a list of {size} numbers")
    return np.array([finite_number(v, where) for v in value])


def _set_link(pm: Any, j: int, terms: dict[str, Any], where: str) -> None:
    import pinocchio as pin  # noqa: PLC0415

    now = pm.inertias[j + 1]
    mass = finite_number(terms.get("mass_kg", now.mass), f"{where}: mass_kg")
    if mass < 0:
        raise ConfigError(f"{where}: mass_kg {mass} is negative")
    com = (_vector(terms["com_m"], 3, f"{where}: com_m") if "com_m" in terms
           else np.array(now.lever))  # fmt: skip
    if "inertia_com_kgm2" in terms:
        xx, xy, yy, xz, yz, zz = _vector(terms["inertia_com_kgm2"], 6, f"{where}: inertia_com_kgm2")
        inertia = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
    else:
        inertia = np.array(now.inertia)
    pm.inertias[j + 1] = pin.Inertia(mass, com, inertia)


def _dfki(model: RobotModel, data: Mapping[str, Any], p: Path) -> RobotModel:
    unknown = sorted(set(data) - set(DFKI_TERMS))
    missing = [k for k in DFKI_REQUIRED if k not in data]
    if unknown or missing:
        raise ConfigError(
            f"{p}: a DFKI double-pendulum parameter file"
            + (f" with unknown terms {unknown}" if unknown else "")
            + (f" lacks {missing}" if missing else "")
        )
    if model.dof != 2:
        raise ConfigError(
            f"{p}: a double pendulum's parameters; {model.source} has {model.dof} movable "
            f"joints ({list(model.joint_names)})"
        )
    import pinocchio as pin  # noqa: PLC0415

    def number(key: str, default: float) -> float:
        return finite_number(data.get(key, default), f"{p}: {key}")

    pm = pin.Model(model.pin_model)
    notes = list(model.notes)
    gear, rotor = number("gr", 0.0), number("Ir", 0.0)
    viscous, coulomb = np.zeros(2), np.zeros(2)
    for j in range(2):
        i = j + 1
        now = pm.inertias[i]
        axis = _axis(pm, i)
        v = int(pm.joints[i].idx_v)
        lever = np.array(now.lever)
        along = axis * float(axis @ lever)
        across = lever - along
        if np.linalg.norm(across) < 1e-9:
            raise ConfigError(
                f"{p}: r{i}: the URDF puts link {i}'s centre of mass on its joint's axis, so "
                "there is no direction to place it at r along"
            )
        mass, r, about_axis = number(f"m{i}", 0.0), number(f"r{i}", 0.0), number(f"I{i}", 0.0)
        com = along + r * across / np.linalg.norm(across)
        inertia = np.array(now.inertia)
        # the inertia about the axis through the centre of mass: I about the joint less m r^2
        target = about_axis - mass * r**2
        if target < 0:
            raise ConfigError(f"{p}: I{i} {about_axis} is below m{i} r{i}^2 ({mass * r**2:.4g})")
        inertia += (target - float(axis @ inertia @ axis)) * np.outer(axis, axis)
        pm.inertias[i] = pin.Inertia(mass, com, inertia)
        pm.armature[v] = gear**2 * rotor
        viscous[j] = number(f"b{i}", 0.0)
        coulomb[j] = number(f"cf{i}", 0.0) * math.pi / 2
        if f"tl{i}" in data:
            pm.effortLimit[v] = number(f"tl{i}", 0.0)
        if i == 1 and "l1" in data:  # the URDF's geometry is kept: a note where they differ
            length = number("l1", 0.0)
            reach = np.array(pm.jointPlacements[2].translation)
            across_reach = float(np.linalg.norm(reach - axis * float(axis @ reach)))
            if abs(across_reach - length) > 0.05 * length:
                notes.append(f"{p.name}: l1 {length} m, the URDF's joint 2 is "
                             f"{across_reach:.4g} m from joint 1 (kept)")  # fmt: skip
    if "g" in data:
        pm.gravity.linear = np.array([0.0, 0.0, -number("g", 9.81)])
    if gear * rotor:
        notes.append(
            f"{p.name}: the rotor's inertia gr^2 Ir as each joint's armature; its terms off "
            "the diagonal (Ir in M00, -gr Ir in M01) have no place in a URDF and are left out"
        )
    notes.append(f"{p.name}: Coulomb friction cf pi/2 (their cf atan(100 q') levels off there)")
    friction = JointFriction(viscous, coulomb, model.friction.smoothing_rad_s)
    return RobotModel(pm, friction, f"{model.source} + {p.name}", notes)


def _axis(pm: Any, i: int) -> np.ndarray:
    """Joint ``i``'s axis of rotation in its own frame (a unit vector)."""
    import pinocchio as pin  # noqa: PLC0415

    data = pm.createData()
    q = pin.neutral(pm)
    pin.computeJointJacobians(pm, data, q)
    motion = pin.getJointJacobian(pm, data, i, pin.ReferenceFrame.LOCAL)[:, pm.joints[i].idx_v]
    angular = np.array(motion[3:], dtype=float)
    out: np.ndarray = angular / float(np.linalg.norm(angular))
    return out
