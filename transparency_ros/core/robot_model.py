"""A robot's rigid-body model from its URDF (Pinocchio): M(q), C(q, q') and g(q) of the joints,
with the joint friction of the URDF's ``<dynamics damping friction>`` tags.

The URDF comes as robot_state_publisher takes it: the XML itself (the ``robot_description``
string) or a file. Before Pinocchio reads it, the XML is checked here so that a file that does
not load says which file and which element: Pinocchio's parser (urdfdom) only raises "does not
contain a valid URDF model" and prints the reason to the console. One fault is common enough
to accept with a note, as Gazebo and Drake do: a joint whose parent is a ``world`` link that the
file never defines (the robot is welded to the world).

Joints are 1-DoF (revolute, continuous, prismatic); a continuous joint's angle is given as an
angle like a revolute one. Arrays are in the order of :attr:`RobotModel.joint_names` (the
URDF's tree order); :meth:`RobotModel.index` maps the names of a /joint_states message to it.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from transparency_ros.core.errors import ConfigError

FloatArray = npt.NDArray[np.float64]
WORLD = "world"
COULOMB_SMOOTHING_RAD_S = 0.05  # Coulomb friction as tanh(v / this): no chatter at rest
SUPPORTED = ("revolute", "continuous", "prismatic")


class UrdfError(ConfigError):
    """A URDF that cannot be read, or joints that do not match it; the message names the file
    (or ``robot_description``) and the element."""


@dataclass(frozen=True)
class JointFriction:
    """Per joint: viscous [N m s/rad] and Coulomb [N m] friction, F(v) = b v + c tanh(v / eps)."""

    viscous: FloatArray
    coulomb: FloatArray
    smoothing_rad_s: float = COULOMB_SMOOTHING_RAD_S

    def torque(self, v: FloatArray) -> FloatArray:
        return np.asarray(
            self.viscous * v + self.coulomb * np.tanh(v / self.smoothing_rad_s), dtype=float
        )


@dataclass
class RobotModel:
    """The joints' dynamics M(q) q'' + C(q, q') q' + g(q) + F(q') = tau + tau_ext."""

    pin_model: Any
    friction: JointFriction
    source: str  # the file, or "robot_description"
    notes: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        import pinocchio as pin  # noqa: PLC0415 - a heavy import, only where a model is built

        self._pin = pin
        self._data = self.pin_model.createData()
        names, idx_q, nq = [], [], []
        for joint_id in range(1, self.pin_model.njoints):
            names.append(str(self.pin_model.names[joint_id]))
            idx_q.append(int(self.pin_model.joints[joint_id].idx_q))
            nq.append(int(self.pin_model.joints[joint_id].nq))
        self.joint_names: tuple[str, ...] = tuple(names)
        self._idx_q = np.array(idx_q)
        self._continuous = np.array(nq) == 2  # (cos, sin) in Pinocchio's configuration
        self._q = np.zeros(self.pin_model.nq)

    @property
    def dof(self) -> int:
        return len(self.joint_names)

    @classmethod
    def from_urdf(cls, urdf: str | Path) -> RobotModel:
        """From a URDF file or its XML (as in ``robot_description``)."""
        text, where = _read(urdf)
        root, notes = _checked(text, where)
        import pinocchio as pin  # noqa: PLC0415

        try:
            model = pin.buildModelFromXML(ET.tostring(root, encoding="unicode"))
        except (ValueError, RuntimeError) as err:
            raise UrdfError(f"{where}: Pinocchio could not build a model: {err}") from err
        if model.nv != model.njoints - 1:
            raise UrdfError(f"{where}: only 1-DoF joints are supported ({SUPPORTED})")
        friction = JointFriction(
            np.array(model.damping, dtype=float), np.array(model.friction, dtype=float)
        )
        return cls(model, friction, where, notes)

    def index(self, names: Sequence[str], where: str = "/joint_states") -> npt.NDArray[np.int64]:
        """For each of the model's joints, its position in ``names``; a clear error when a
        joint of the model is not among them."""
        position = {n: i for i, n in enumerate(names)}
        missing = [n for n in self.joint_names if n not in position]
        if missing:
            raise UrdfError(
                f"{where} has no joint {', '.join(repr(n) for n in missing)} of {self.source} "
                f"(it has {list(names)}; the model's joints: {list(self.joint_names)})"
            )
        return np.array([position[n] for n in self.joint_names], dtype=np.int64)

    def configuration(self, q: FloatArray) -> FloatArray:
        """Pinocchio's configuration vector for joint angles ``q`` (continuous: cos, sin)."""
        out = self._q
        for k, (i, cont) in enumerate(zip(self._idx_q, self._continuous, strict=True)):
            if cont:
                out[i], out[i + 1] = math.cos(q[k]), math.sin(q[k])
            else:
                out[i] = q[k]
        return out

    def child_link(self, joint: str) -> str:
        """The link ``joint`` moves (its child in the URDF; the TF frame a torque about the
        joint is expressed in): the first body Pinocchio attaches to it."""
        joint_id = self.pin_model.getJointId(joint)
        for frame in self.pin_model.frames:
            if frame.type == self._pin.FrameType.BODY and frame.parentJoint == joint_id:
                return str(frame.name)
        raise UrdfError(f"joint {joint!r} moves no link")

    def mass_matrix(self, q: FloatArray) -> FloatArray:
        m = self._pin.crba(self.pin_model, self._data, self.configuration(q))
        return np.asarray(np.triu(m) + np.triu(m, 1).T, dtype=float)  # crba fills the upper half

    def coriolis_matrix(self, q: FloatArray, v: FloatArray) -> FloatArray:
        c = self._pin.computeCoriolisMatrix(self.pin_model, self._data, self.configuration(q), v)
        return np.array(c, dtype=float)

    def gravity(self, q: FloatArray) -> FloatArray:
        g = self._pin.computeGeneralizedGravity(self.pin_model, self._data, self.configuration(q))
        return np.array(g, dtype=float)

    def momentum_terms(self, q: FloatArray, v: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(p, beta): the generalized momentum M(q) v and beta = g(q) - C(q, v)^T v, the part of
        p' = tau - beta - F + tau_ext that the model knows."""
        m = self.mass_matrix(q)
        c = self.coriolis_matrix(q, v)
        return m @ v, self.gravity(q) - c.T @ v

    def friction_torque(self, v: FloatArray) -> FloatArray:
        return self.friction.torque(v)

    def forward_dynamics(self, q: FloatArray, v: FloatArray, tau: FloatArray) -> FloatArray:
        """q'' for the joint torques ``tau`` (friction included), for tests and simulation."""
        a = self._pin.aba(
            self.pin_model, self._data, self.configuration(q), v, tau - self.friction.torque(v)
        )
        return np.array(a, dtype=float)


def _read(urdf: str | Path) -> tuple[str, str]:
    if isinstance(urdf, str) and urdf.lstrip().startswith("<"):
        return urdf, "robot_description"
    path = Path(urdf)
    try:
        return path.read_text(encoding="utf-8"), str(path)
    except OSError as err:
        raise UrdfError(f"{path}: cannot read the URDF: {err.strerror or err}") from err


def _checked(text: str, where: str) -> tuple[ET.Element, list[str]]:
    """The URDF's root, checked: XML, a <robot>, links and joints that refer to links it
    defines (an undefined ``world`` parent is added, with a note), supported joint types."""
    try:
        root = ET.fromstring(text)
    except ET.ParseError as err:
        raise UrdfError(f"{where}: not XML ({err})") from err
    if root.tag != "robot":
        raise UrdfError(f"{where}: the root element is <{root.tag}>, not <robot>")
    links = {link.get("name") for link in root.findall("link")}
    notes: list[str] = []
    for joint in root.findall("joint"):
        name, kind = joint.get("name"), joint.get("type")
        for end in ("parent", "child"):
            element = joint.find(end)
            link = element.get("link") if element is not None else None
            if link is None:
                raise UrdfError(f"{where}: joint {name!r} has no <{end} link=...>")
            if link in links:
                continue
            if end == "parent" and link == WORLD:
                root.insert(0, ET.Element("link", {"name": WORLD}))
                links.add(WORLD)
                notes.append(
                    f"{where}: joint {name!r} names parent link 'world', which the file does "
                    "not define; taken as the fixed world (as Gazebo and Drake do)"
                )
                continue
            raise UrdfError(
                f"{where}: joint {name!r} names {end} link {link!r}, which the file does not "
                f"define (links: {sorted(n for n in links if n)})"
            )
        if kind not in {*SUPPORTED, "fixed"}:
            raise UrdfError(
                f"{where}: joint {name!r} is of type {kind!r}; supported: {SUPPORTED} and fixed"
            )
    return root, notes
