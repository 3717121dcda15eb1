"""Generalized-momentum observer: a second contact estimator, beyond the paper.

For one joint J w' = tau_m - tau_f(w) + tau_ext, the residual

    r(t) = K_o [ J w(t) - J w(0) - integral_0^t (tau_m - tau_f(w) + r) ds ]

follows the external torque through a first-order lag, r' = K_o (tau_ext - r). It needs the
commanded (drive) torque, the velocity and an actuator model (inertia, Coulomb and viscous
friction from Table 1); the position-error estimate of eq. (1) needs none of these, which is the
paper's argument. Time is passed in.

For a robot (:class:`RobotMomentumObserver`, De Luca's observer) the momentum is p = M(q) q' and

    r(t) = K_o [ p(t) - p(0) - integral_0^t (tau - beta(q, q') - F(q') + r) ds ],
    beta = g(q) - C(q, q')^T q',

one residual per joint, each following its joint's external torque through a first-order lag.
The model (:class:`transparency_ros.core.robot_model.RobotModel` from a URDF, or any object with
the same ``dof``, ``momentum_terms`` and ``friction_torque``) is passed in.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import numpy.typing as npt

from transparency_ros.core.config import ActuatorParams
from transparency_ros.core.estimator import EstimatorError


@dataclass(frozen=True)
class FrictionModel:
    inertia_kgm2: float
    viscous_nms_per_rad: float
    coulomb_nm: float
    smoothing_rad_s: float = 0.05  # Coulomb term as tanh(w / smoothing): no chatter at rest

    @classmethod
    def from_actuator(cls, actuator: ActuatorParams, arm_inertia_kgm2: float = 0.0
                      ) -> FrictionModel:  # fmt: skip
        return cls(
            actuator.reflected_inertia_kgm2 + arm_inertia_kgm2,
            actuator.viscous_damping_nms_per_rad,
            actuator.coulomb_friction_nm,
        )

    def friction_nm(self, velocity: float) -> float:
        return self.viscous_nms_per_rad * velocity + self.coulomb_nm * math.tanh(
            velocity / self.smoothing_rad_s
        )


class MomentumObserver:
    def __init__(self, model: FrictionModel, gain_per_s: float) -> None:
        if not (model.inertia_kgm2 > 0 and math.isfinite(gain_per_s) and gain_per_s > 0):
            raise EstimatorError("momentum observer needs inertia > 0 and a gain K_o > 0")
        self.model = model
        self.gain_per_s = gain_per_s
        self.reset()

    def reset(self) -> None:
        self._p0: float | None = None
        self._integral = 0.0
        self._last: tuple[float, float, float] | None = None  # stamp, velocity, torque
        self.residual_nm = 0.0

    def update(self, stamp_s: float, velocity_rad_s: float, drive_torque_nm: float) -> float:
        """Feed one sample; return the residual (estimate of the external torque) [N m]."""
        p = self.model.inertia_kgm2 * velocity_rad_s
        if self._last is None or self._p0 is None:
            self._p0 = p
            self._last = (stamp_s, velocity_rad_s, drive_torque_nm)
            return self.residual_nm
        last_stamp, last_v, last_tau = self._last
        dt = stamp_s - last_stamp
        if dt <= 0:
            raise EstimatorError(f"stamps must increase (got {stamp_s} after {last_stamp})")
        # rectangle rule with the previous sample (causal)
        self._integral += (last_tau - self.model.friction_nm(last_v) + self.residual_nm) * dt
        self.residual_nm = self.gain_per_s * (p - self._p0 - self._integral)
        self._last = (stamp_s, velocity_rad_s, drive_torque_nm)
        return self.residual_nm


FloatArray = npt.NDArray[np.float64]


class RobotDynamics(Protocol):
    """What the observer needs of a robot model."""

    @property
    def dof(self) -> int: ...

    def momentum_terms(self, q: FloatArray, v: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(M(q) v, g(q) - C(q, v)^T v)."""
        ...

    def friction_torque(self, v: FloatArray) -> FloatArray: ...


class RobotMomentumObserver:
    """The generalized-momentum observer of a robot's joints; time in integer nanoseconds."""

    def __init__(self, model: RobotDynamics, gain_per_s: float | FloatArray) -> None:
        gain = np.broadcast_to(np.asarray(gain_per_s, dtype=float), (model.dof,)).copy()
        if not np.all(np.isfinite(gain) & (gain > 0)):
            raise EstimatorError(f"momentum observer gains K_o must be > 0, got {gain.tolist()}")
        self.model = model
        self.gain_per_s = gain
        self.reset()

    @property
    def last_stamp_ns(self) -> int | None:
        """The stamp of the latest sample taken, if any."""
        return None if self._last is None else self._last[0]

    def reset(self) -> None:
        self._p0: FloatArray | None = None
        self._integral = np.zeros(self.model.dof)
        self._last: tuple[int, FloatArray] | None = None  # stamp, beta + friction: latest sample
        self._held_nm: FloatArray | None = None  # the torque given with the latest sample
        self.residual_nm = np.zeros(self.model.dof)

    def update(self, stamp_ns: int, q: FloatArray, v: FloatArray, tau_nm: FloatArray) -> FloatArray:
        """Feed one sample (joint positions, velocities, applied torques in the model's joint
        order); return the residual, the estimate of the external torques [N m]. The torque
        given with a sample is the one applied until the next."""
        tau = self._checked("torque", tau_nm)
        held = tau if self._held_nm is None else self._held_nm
        residual = self.step(stamp_ns, q, v, held)
        self._held_nm = tau
        return residual

    def step(
        self, stamp_ns: int, q: FloatArray, v: FloatArray, applied_since_last: FloatArray
    ) -> FloatArray:
        """Feed one sample with the torque applied since the previous one (unused for the
        first), for a caller that learns it only now (a node gets the command for an interval
        after the sample that opened it); return the residual [N m]."""
        q, v = self._checked("position", q), self._checked("velocity", v)
        applied = self._checked("torque applied since the last sample", applied_since_last)
        if self._last is not None and stamp_ns <= self._last[0]:
            raise EstimatorError(f"stamps must increase (got {stamp_ns} ns after {self._last[0]})")
        p, beta = self.model.momentum_terms(q, v)
        known = beta + self.model.friction_torque(v)  # the rate of p is tau - known + tau_ext
        if self._last is None or self._p0 is None:
            self._p0 = p
            self._last = (stamp_ns, known)
            return self.residual_nm.copy()
        last_stamp, last_known = self._last
        dt = (stamp_ns - last_stamp) * 1e-9
        # rectangle rule with the previous sample (causal), as for one joint
        self._integral += (applied - last_known + self.residual_nm) * dt
        self.residual_nm = self.gain_per_s * (p - self._p0 - self._integral)
        self._last = (stamp_ns, known)
        return self.residual_nm.copy()

    def _checked(self, label: str, values: FloatArray) -> FloatArray:
        x = np.asarray(values, dtype=float)
        if x.shape != (self.model.dof,):
            raise EstimatorError(f"{label}: expected {self.model.dof} joints, got shape {x.shape}")
        if not np.all(np.isfinite(x)):
            raise EstimatorError(f"{label} is not finite: {x.tolist()}")
        return x

    def run(
        self,
        stamps_ns: npt.NDArray[np.int64],
        q: FloatArray,
        v: FloatArray,
        tau_nm: FloatArray,
    ) -> FloatArray:
        """A whole recording, (samples, joints) each, from a reset: the residuals, (samples,
        joints), as :meth:`update` gives them one by one."""
        self.reset()
        return np.array(
            [
                self.update(int(t), qi, vi, ti)
                for t, qi, vi, ti in zip(stamps_ns, q, v, tau_nm, strict=True)
            ]
        )
