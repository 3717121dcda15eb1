"""The paper's contact model (Sec. 3.2): inelastic impact, eq. (2), closed form eq. (3), eq. (4).

A shuttle of mass m_s hits the tip of an arm of length r on the actuator output at speed v_s,t.
The impact is perfectly inelastic, so the shaft starts at

    omega_c = m_s r v_s,t / (J_m + m_s r^2)

and then, with theta_d = 0 and the virtual spring k_s of the impedance controller,

    J theta'' = -k_s theta - beta theta' - tau_coul,   theta(0) = 0, theta'(0) = omega_c     (2)

with J = J_m + m_s r^2 and beta = b_v + k_d. Eq. (2) holds while theta' > 0 (Coulomb friction
opposes the motion), which is the only interval the detector cares about: theta rises
monotonically until theta' = 0 at t_stop, so the threshold theta_th is either crossed once
before t_stop (contact detected at t_r) or never (friction and the spring stop the shaft first:
the vertical asymptote of Fig. 2).

Closed form. With x = theta + tau_coul/k_s, alpha = beta/2J, w0^2 = k_s/J and q = w0^2 - alpha^2:

    x(t)      = e^{-alpha t} [ x0 C(t) + (omega_c + alpha x0) S(t) ],     x0 = tau_coul / k_s
    theta'(t) = e^{-alpha t} [ omega_c C(t) - (alpha omega_c + w0^2 x0) S(t) ]

where C = cos(sqrt(q) t), S = sin(sqrt(q) t)/sqrt(q) when underdamped (q > 0), C = cosh, S =
sinh/sqrt(-q) when overdamped (q < 0), and C = 1, S = t when critically damped (q = 0). This is
eq. (3) of the paper rewritten so that all three regimes are one continuous expression that
stays accurate near critical damping (eq. (3) divides by Delta = sqrt(beta^2 - 4 k_s J), which
vanishes there). Note: with Table 1 and k_s = 2 N m/rad, T2822 and U10GB are *overdamped*
(zeta ~ 2.9 and 5.4), although the paper's text calls Delta complex in all four cases.

t_stop has a closed form too (theta' = 0), and t_r is the root of theta(t) = theta_th on
[0, t_stop], found by a bracketed Newton iteration vectorised over all energies.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt
from scipy.optimize import brentq

from transparency_ros.core.config import (
    ActuatorParams,
    DropTestConfig,
    get_actuator,
    load_drop_test,
)
from transparency_ros.core.errors import ModelError, shown

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]

# |zeta - 1| below this is reported as critically damped (the formulas are continuous anyway).
CRITICAL_DAMPING_RTOL = 1e-9
_NEWTON_MAX_ITER = 200


class DampingRegime(str, Enum):
    UNDERDAMPED = "underdamped"
    CRITICALLY_DAMPED = "critically_damped"
    OVERDAMPED = "overdamped"


class ContactResult(NamedTuple):
    """Model outcome for N collision energies; every array has shape (N,).

    Quantities that only exist when contact is detected (t_r, v_s,e, Delta E) are NaN where
    ``detected`` is False.
    """

    energy_j: FloatArray  # T = 1/2 m_s v_s,t^2
    v_s_t_m_s: FloatArray  # shuttle speed at true contact
    omega_c_rad_s: FloatArray  # shaft speed just after the inelastic impact
    t_stop_s: FloatArray  # time at which theta' reaches 0 (end of the first swing)
    theta_max_rad: FloatArray  # deflection at t_stop
    detected: BoolArray  # theta_max >= threshold
    t_r_s: FloatArray  # detection delay t_e - t_t
    v_s_e_m_s: FloatArray  # shuttle (= arm tip) speed at detection
    delta_e_j: FloatArray  # eq. (4): 1/2 m_s (v_s,t^2 - v_s,e^2)


@dataclass(frozen=True)
class ContactModel:
    """Eq. (2) for one actuator on the drop-test rig. Build it with :meth:`from_config`."""

    actuator: str
    actuator_inertia_kgm2: float  # J_m = J_r + arm inertia
    shuttle_mass_kg: float  # m_s
    arm_length_m: float  # r
    k_s_nm_per_rad: float
    damping_nms_per_rad: float  # beta = b_v + k_d
    coulomb_friction_nm: float
    threshold_rad: float

    def __post_init__(self) -> None:
        for name in (
            "actuator_inertia_kgm2",
            "shuttle_mass_kg",
            "arm_length_m",
            "k_s_nm_per_rad",
            "threshold_rad",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ModelError(f"ContactModel.{name} must be finite and > 0, got {shown(value)}")
        for name in ("damping_nms_per_rad", "coulomb_friction_nm"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ModelError(f"ContactModel.{name} must be finite and >= 0, got {shown(value)}")

    @classmethod
    def from_config(
        cls,
        actuator: ActuatorParams,
        drop_test: DropTestConfig,
        *,
        arm_inertia_kgm2: float | None = None,
        shuttle_mass_kg: float | None = None,
        arm_length_m: float | None = None,
        k_s_nm_per_rad: float | None = None,
        k_d_nms_per_rad: float | None = None,
        threshold_rad: float | None = None,
    ) -> ContactModel:
        """The paper's setup for ``actuator``; any keyword overrides the configured value."""

        def pick(override: float | None, default: float) -> float:
            return default if override is None else float(override)

        arm_inertia = pick(arm_inertia_kgm2, drop_test.arm_inertia_kgm2)
        k_d = pick(k_d_nms_per_rad, drop_test.k_d_nms_per_rad)
        if arm_inertia < 0 or k_d < 0:
            raise ModelError("arm inertia and k_d must be >= 0")
        return cls(
            actuator=actuator.name,
            actuator_inertia_kgm2=actuator.reflected_inertia_kgm2 + arm_inertia,
            shuttle_mass_kg=pick(shuttle_mass_kg, drop_test.shuttle_mass_for(actuator.name)),
            arm_length_m=pick(arm_length_m, drop_test.arm_length_m),
            k_s_nm_per_rad=pick(k_s_nm_per_rad, drop_test.k_s_nm_per_rad),
            damping_nms_per_rad=actuator.viscous_damping_nms_per_rad + k_d,
            coulomb_friction_nm=actuator.coulomb_friction_nm,
            threshold_rad=pick(threshold_rad, drop_test.threshold_rad),
        )

    # ----------------------------------------------------------------- derived constants

    @property
    def total_inertia_kgm2(self) -> float:
        """J = J_m + m_s r^2, the inertia moving after the impact."""
        return self.actuator_inertia_kgm2 + self.shuttle_mass_kg * self.arm_length_m**2

    @property
    def alpha_per_s(self) -> float:
        return self.damping_nms_per_rad / (2.0 * self.total_inertia_kgm2)

    @property
    def natural_frequency_sq(self) -> float:
        """w0^2 = k_s / J [1/s^2]."""
        return self.k_s_nm_per_rad / self.total_inertia_kgm2

    @property
    def damping_ratio(self) -> float:
        return self.alpha_per_s / math.sqrt(self.natural_frequency_sq)

    @property
    def regime(self) -> DampingRegime:
        zeta = self.damping_ratio
        if abs(zeta - 1.0) <= CRITICAL_DAMPING_RTOL:
            return DampingRegime.CRITICALLY_DAMPED
        return DampingRegime.UNDERDAMPED if zeta < 1.0 else DampingRegime.OVERDAMPED

    @property
    def _x0(self) -> float:
        return self.coulomb_friction_nm / self.k_s_nm_per_rad

    @property
    def _q(self) -> float:
        return self.natural_frequency_sq - self.alpha_per_s**2

    # ----------------------------------------------------------------- impact

    def impact_speed(self, energy_j: npt.ArrayLike) -> FloatArray:
        """v_s,t = sqrt(2 T / m_s)."""
        energy = _as_energy(energy_j)
        return np.sqrt(2.0 * energy / self.shuttle_mass_kg)

    def omega_c(self, v_s_t_m_s: npt.ArrayLike) -> FloatArray:
        """Shaft speed just after the inelastic impact: m_s r v / (J_m + m_s r^2)."""
        v = np.asarray(v_s_t_m_s, dtype=np.float64)
        return self.shuttle_mass_kg * self.arm_length_m * v / self.total_inertia_kgm2

    # ----------------------------------------------------------------- trajectory (eq. 3)

    def _propagators(self, t: FloatArray) -> tuple[FloatArray, FloatArray]:
        """e^{-alpha t} C(t) and e^{-alpha t} S(t), accurate in all three regimes."""
        alpha, q = self.alpha_per_s, self._q
        if q > 0.0:
            w = math.sqrt(q)
            decay = np.exp(-alpha * t)
            return decay * np.cos(w * t), decay * t * np.sinc(w * t / math.pi)
        g = math.sqrt(-q)
        slow = np.exp(-(self.natural_frequency_sq / (alpha + g)) * t)  # e^{(g - alpha) t}
        u = 2.0 * g * t
        fast_ratio = np.exp(-u)  # e^{-2 g t}
        safe_u = np.where(u > 1e-12, u, 1.0)
        h = np.where(u > 1e-12, -np.expm1(-u) / safe_u, 1.0 - 0.5 * u)  # (1 - e^{-u}) / u
        return slow * 0.5 * (1.0 + fast_ratio), slow * t * h

    def theta(self, t_s: npt.ArrayLike, omega_c_rad_s: npt.ArrayLike) -> FloatArray:
        """Deflection theta(t) [rad] of eq. (3), valid for 0 <= t <= t_stop."""
        t = np.asarray(t_s, dtype=np.float64)
        w = np.asarray(omega_c_rad_s, dtype=np.float64)
        x0 = self._x0
        ec, es = self._propagators(t)
        return x0 * (ec - 1.0) + (w + self.alpha_per_s * x0) * es

    def theta_dot(self, t_s: npt.ArrayLike, omega_c_rad_s: npt.ArrayLike) -> FloatArray:
        """Shaft speed theta'(t) [rad/s], valid for 0 <= t <= t_stop."""
        t = np.asarray(t_s, dtype=np.float64)
        w = np.asarray(omega_c_rad_s, dtype=np.float64)
        ec, es = self._propagators(t)
        return w * ec - (self.alpha_per_s * w + self.natural_frequency_sq * self._x0) * es

    def stop_time(self, omega_c_rad_s: npt.ArrayLike) -> FloatArray:
        """First time at which theta' = 0 (closed form); 0 where omega_c = 0."""
        w = np.asarray(omega_c_rad_s, dtype=np.float64)
        denom = self.alpha_per_s * w + self.natural_frequency_sq * self._x0
        safe = np.where(denom > 0.0, denom, 1.0)
        c = np.where(denom > 0.0, w / safe, np.inf)  # tan(w_d t) = w_d c, tanh(g t) = g c
        q = self._q
        if q > 0.0:
            wd = math.sqrt(q)
            return np.asarray(np.arctan(wd * c) / wd, dtype=np.float64)
        g = math.sqrt(-q)
        if g == 0.0:
            return np.asarray(c, dtype=np.float64)
        return np.asarray(np.arctanh(g * c) / g, dtype=np.float64)

    # ----------------------------------------------------------------- detection (eq. 4)

    def solve(self, energy_j: npt.ArrayLike) -> ContactResult:
        """Detection delay, speed at detection and energy loss for every collision energy."""
        energy = np.atleast_1d(_as_energy(energy_j)).astype(np.float64)
        v_t = self.impact_speed(energy)
        w_c = self.omega_c(v_t)
        t_stop = self.stop_time(w_c)
        theta_max = self.theta(t_stop, w_c)
        detected = theta_max >= self.threshold_rad
        t_r = np.full_like(energy, np.nan)
        if np.any(detected):
            t_r[detected] = self._threshold_time(w_c[detected], t_stop[detected])
        v_e = np.full_like(energy, np.nan)
        v_e[detected] = self.theta_dot(t_r[detected], w_c[detected]) * self.arm_length_m
        delta_e = 0.5 * self.shuttle_mass_kg * (v_t**2 - v_e**2)
        return ContactResult(
            energy_j=energy,
            v_s_t_m_s=v_t,
            omega_c_rad_s=w_c,
            t_stop_s=t_stop,
            theta_max_rad=theta_max,
            detected=detected,
            t_r_s=t_r,
            v_s_e_m_s=v_e,
            delta_e_j=delta_e,
        )

    def _threshold_time(self, w_c: FloatArray, t_stop: FloatArray) -> FloatArray:
        """Root of theta(t) = threshold on [0, t_stop] where theta is increasing.

        Newton steps safeguarded by the bracket (bisection when Newton would leave it);
        vectorised: every energy iterates at once until all brackets have converged.
        """
        lo = np.zeros_like(t_stop)
        hi = t_stop.copy()
        t = 0.5 * (lo + hi)
        target = self.threshold_rad
        for _ in range(_NEWTON_MAX_ITER):
            f = self.theta(t, w_c) - target
            lo = np.where(f < 0.0, t, lo)
            hi = np.where(f >= 0.0, t, hi)
            slope = self.theta_dot(t, w_c)
            with np.errstate(divide="ignore", invalid="ignore"):
                newton = t - f / slope
            inside = np.isfinite(newton) & (newton > lo) & (newton < hi)
            t_next = np.where(inside, newton, 0.5 * (lo + hi))
            if np.all(np.abs(t_next - t) <= 4.0 * np.finfo(np.float64).eps * np.abs(t_next)):
                return np.asarray(t_next, dtype=np.float64)
            t = t_next
        return np.asarray(t, dtype=np.float64)

    def min_detectable_energy(self) -> float:
        """The vertical asymptote of Fig. 2: smallest T whose first swing reaches the threshold.

        theta_max grows monotonically with omega_c, so this is a scalar root in omega_c.
        """

        def excess(w: float) -> float:
            w_arr = np.array([w])
            return float(self.theta(self.stop_time(w_arr), w_arr)[0]) - self.threshold_rad

        high = 1.0
        while excess(high) < 0.0:
            high *= 2.0
            if high > 1e9:  # pragma: no cover - only for absurd parameters
                raise ModelError(f"{self.actuator}: threshold unreachable at any energy")
        w_star = brentq(excess, 0.0, high, xtol=1e-15, rtol=4 * np.finfo(float).eps)
        v_star = w_star * self.total_inertia_kgm2 / (self.shuttle_mass_kg * self.arm_length_m)
        return float(0.5 * self.shuttle_mass_kg * v_star**2)


def _as_energy(energy_j: npt.ArrayLike) -> FloatArray:
    energy = np.asarray(energy_j, dtype=np.float64)
    if energy.ndim > 1:
        raise ModelError(
            f"collision energy must be a scalar or 1-D array, got shape {energy.shape}"
        )
    bad = ~np.isfinite(energy) | (energy < 0.0)
    if np.any(bad):
        first = np.atleast_1d(energy)[np.atleast_1d(bad)][0]
        raise ModelError(f"collision energy must be finite and >= 0 J, got {shown(first)}")
    return energy


def model_for(
    actuator: str,
    *,
    actuators_path: str | None = None,
    drop_test_path: str | None = None,
    **overrides: float | None,
) -> ContactModel:
    """Convenience: the configured contact model of a Table 1 actuator by name."""
    return ContactModel.from_config(
        get_actuator(actuator, actuators_path), load_drop_test(drop_test_path), **overrides
    )


def restitution_damping_ratio(restitution: Any) -> Any:
    """Damping ratio of a spring-damper contact that rebounds with ``restitution`` from an
    immovable body: zeta = -ln e / sqrt(pi^2 + ln^2 e) (floats or numpy arrays)."""
    log_e = np.log(restitution)
    return -log_e / np.sqrt(np.pi**2 + log_e**2)
