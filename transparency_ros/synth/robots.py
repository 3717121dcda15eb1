"""Robot descriptions for tests and benchmarks: a planar chain of any number of joints."""

from __future__ import annotations


def chain_urdf(n: int, *, damping: float = 0.01, friction: float = 0.05) -> str:
    """The URDF of a planar chain of ``n`` revolute joints about x (0.2 m links of 0.5 kg,
    their centres of mass 0.1 m down), hanging down at q = 0, with the given joint friction."""
    if n < 1:
        raise ValueError(f"a chain needs at least one joint, got {n}")
    links = ['<link name="base"/>']
    joints = []
    for i in range(n):
        links.append(
            f'<link name="l{i}"><inertial><origin xyz="0 0 -0.1"/><mass value="0.5"/>'
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
