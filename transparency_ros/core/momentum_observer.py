"""Generalized-momentum observer: a second contact estimator, beyond the paper.

For one joint J w' = tau_m - tau_f(w) + tau_ext, the residual

    r(t) = K_o [ J w(t) - J w(0) - integral_0^t (tau_m - tau_f(w) + r) ds ]

follows the external torque through a first-order lag, r' = K_o (tau_ext - r). It needs the
commanded (drive) torque, the velocity and an actuator model (inertia, Coulomb and viscous
friction from Table 1); the position-error estimate of eq. (1) needs none of these, which is the
paper's argument. Time is passed in.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

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
