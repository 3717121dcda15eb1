"""Robots for tests and benchmarks: a planar chain of any number of joints (its URDF) and its
motion under a PD tracking controller, with external torques and a command delay."""

from __future__ import annotations

import math
from typing import Protocol

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


class Dynamics(Protocol):
    @property
    def dof(self) -> int: ...

    def forward_dynamics(self, q: FloatArray, v: FloatArray, tau: FloatArray) -> FloatArray: ...


def chain_urdf(n: int, *, damping: float = 0.01, friction: float = 0.05, mass: float = 0.5) -> str:
    """The URDF of a planar chain of ``n`` revolute joints about x (0.2 m links of ``mass``
    kg, their centres of mass 0.1 m down), hanging down at q = 0, with the given joint
    friction."""
    if n < 1:
        raise ValueError(f"a chain needs at least one joint, got {n}")
    links = ['<link name="base"/>']
    joints = []
    for i in range(n):
        links.append(
            f'<link name="l{i}"><inertial><origin xyz="0 0 -0.1"/><mass value="{mass}"/>'
            '<inertia ixx="0.002" ixy="0" ixz="0" iyy="0.002" iyz="0" izz="0.0001"/>'
            "</inertial></link>"
        )
        parent = "base" if i == 0 else f"l{i - 1}"
        z = 0.0 if i == 0 else -0.2
        joints.append(
            f'<joint name="j{i}" type="revolute"><parent link="{parent}"/>'
            f'<child link="l{i}"/><origin xyz="0 0 {z}"/><axis xyz="1 0 0"/>'
            '<limit lower="-3.2" upper="3.2" effort="20" velocity="30"/>'
            f'<dynamics damping="{damping}" friction="{friction}"/></joint>'
        )
    return f'<robot name="chain{n}">' + "".join(links + joints) + "</robot>"


def simulate_chain(
    model: Dynamics,
    tau_ext: FloatArray,
    dt: float = 1e-3,
    *,
    delay_steps: int = 0,
    phase: float = 0.0,
) -> tuple[npt.NDArray[np.int64], FloatArray, FloatArray, FloatArray]:
    """The model's motion (RK4, step ``dt``) under a PD controller tracking 0.5 rad sines at
    0.7 Hz about 0.4 rad, from a start on that path, plus ``tau_ext`` (samples, joints). The
    motors apply the command ``delay_steps`` samples late. Returns stamps [ns], q, v and the
    command (samples, joints)."""
    n = model.dof
    w, offsets = 2 * math.pi * 0.7, np.arange(n) + phase
    q, v = 0.4 + 0.5 * np.sin(offsets), 0.5 * w * np.cos(offsets)  # on the path: no kick
    commands: list[FloatArray] = []
    qs, vs = [], []
    for k in range(tau_ext.shape[0]):
        target = 0.4 + 0.5 * np.sin(w * k * dt + offsets)
        commands.append(8.0 * (target - q) - 0.5 * v)
        qs.append(q.copy())
        vs.append(v.copy())
        applied = commands[max(0, k - delay_steps)] + tau_ext[k]

        def f(x: FloatArray, tau: FloatArray = applied) -> FloatArray:
            out: FloatArray = np.r_[x[n:], model.forward_dynamics(x[:n], x[n:], tau)]
            return out

        x = np.r_[q, v]
        k1 = f(x)
        k2 = f(x + dt / 2 * k1)
        k3 = f(x + dt / 2 * k2)
        k4 = f(x + dt * k3)
        x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        q, v = x[:n], x[n:]
    stamps = (np.arange(tau_ext.shape[0]) * round(dt * 1e9)).astype(np.int64)
    return stamps, np.array(qs), np.array(vs), np.array(commands)
