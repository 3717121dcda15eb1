"""The contact model (eq. 2-4) against independent references.

* a numerical integration of eq. (2) (scipy's DOP853 at rtol 1e-12, with event location), which
  shares no code with the closed form;
* the paper's own eq. (3), written out with complex Delta;
* the qualitative results of Fig. 2.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

from transparency_ros.core.contact_model import ContactModel, DampingRegime, model_for
from transparency_ros.core.errors import ModelError

ACTUATORS = ["U10DD", "EC60", "T2822", "U10GB"]
ENERGIES = np.geomspace(0.01, 10.0, 25)
RTOL = 1e-6


def ode_reference(m: ContactModel, energy: float) -> tuple[bool, float, float, float]:
    """Integrate eq. (2) numerically: (detected, t_r, theta_dot at t_r, theta_max)."""
    J = m.total_inertia_kgm2
    v_t = math.sqrt(2 * energy / m.shuttle_mass_kg)
    w_c = m.shuttle_mass_kg * m.arm_length_m * v_t / J

    def rhs(_t: float, y: np.ndarray) -> list[float]:
        theta, omega = y
        torque = -m.k_s_nm_per_rad * theta - m.damping_nms_per_rad * omega - m.coulomb_friction_nm
        return [omega, torque / J]

    def crossed(_t: float, y: np.ndarray) -> float:
        return float(y[0] - m.threshold_rad)

    def stopped(_t: float, y: np.ndarray) -> float:
        return float(y[1])

    crossed.terminal, crossed.direction = True, 1.0  # type: ignore[attr-defined]
    stopped.terminal, stopped.direction = True, -1.0  # type: ignore[attr-defined]
    sol = solve_ivp(
        rhs,
        (0.0, 10.0),
        [0.0, w_c],
        method="DOP853",
        rtol=1e-12,
        atol=1e-15,
        events=[crossed, stopped],
    )
    assert sol.status == 1, "integration ended without an event"
    if sol.t_events[0].size:
        return True, float(sol.t_events[0][0]), float(sol.y_events[0][0][1]), math.nan
    return False, math.nan, math.nan, float(sol.y_events[1][0][0])


@pytest.mark.parametrize("actuator", ACTUATORS)
def test_closed_form_matches_numerical_integration(actuator: str) -> None:
    m = model_for(actuator)
    r = m.solve(ENERGIES)
    detected_somewhere = 0
    for i, energy in enumerate(ENERGIES):
        detected, t_r, w_e, theta_max = ode_reference(m, float(energy))
        assert bool(r.detected[i]) == detected, f"{actuator} at {energy:.4g} J"
        if detected:
            detected_somewhere += 1
            v_e = w_e * m.arm_length_m
            delta_e = 0.5 * m.shuttle_mass_kg * (2 * energy / m.shuttle_mass_kg - v_e**2)
            assert r.t_r_s[i] == pytest.approx(t_r, rel=RTOL)
            assert r.v_s_e_m_s[i] == pytest.approx(v_e, rel=RTOL)
            assert r.delta_e_j[i] == pytest.approx(delta_e, rel=RTOL)
        else:
            assert math.isnan(r.t_r_s[i]) and math.isnan(r.delta_e_j[i])
            assert r.theta_max_rad[i] == pytest.approx(theta_max, rel=RTOL)
    assert 0 < detected_somewhere < len(ENERGIES), "grid should straddle the asymptote"


def _model_with_damping_ratio(zeta: float) -> ContactModel:
    base = model_for("EC60")
    J, k = base.total_inertia_kgm2, base.k_s_nm_per_rad
    return ContactModel(
        actuator=f"zeta={zeta}",
        actuator_inertia_kgm2=base.actuator_inertia_kgm2,
        shuttle_mass_kg=base.shuttle_mass_kg,
        arm_length_m=base.arm_length_m,
        k_s_nm_per_rad=k,
        damping_nms_per_rad=zeta * 2.0 * math.sqrt(k * J),
        coulomb_friction_nm=base.coulomb_friction_nm,
        threshold_rad=base.threshold_rad,
    )


@pytest.mark.parametrize(
    ("zeta", "regime"),
    [
        (0.2, DampingRegime.UNDERDAMPED),
        (1.0, DampingRegime.CRITICALLY_DAMPED),
        (4.0, DampingRegime.OVERDAMPED),
    ],
)
def test_all_three_regimes_match_integration(zeta: float, regime: DampingRegime) -> None:
    m = _model_with_damping_ratio(zeta)
    assert m.regime is regime
    energies = np.geomspace(0.05, 10.0, 12)
    r = m.solve(energies)
    assert r.detected.any()
    for i, energy in enumerate(energies):
        detected, t_r, w_e, _ = ode_reference(m, float(energy))
        assert bool(r.detected[i]) == detected
        if detected:
            assert r.t_r_s[i] == pytest.approx(t_r, rel=RTOL)
            assert r.v_s_e_m_s[i] == pytest.approx(w_e * m.arm_length_m, rel=RTOL)


def test_trajectory_matches_integration_over_the_whole_swing() -> None:
    for zeta in (0.3, 1.0, 1.0 + 1e-7, 1.0 - 1e-7, 3.0):
        m = _model_with_damping_ratio(zeta)
        w_c = 15.0
        t_stop = float(m.stop_time(np.array([w_c]))[0])
        ts = np.linspace(0.0, t_stop, 200)
        J = m.total_inertia_kgm2
        sol = solve_ivp(
            lambda _t, y, m=m, J=J: [
                y[1],
                (-m.k_s_nm_per_rad * y[0] - m.damping_nms_per_rad * y[1] - m.coulomb_friction_nm)
                / J,
            ],
            (0.0, t_stop),
            [0.0, w_c],
            method="DOP853",
            rtol=1e-12,
            atol=1e-15,
            t_eval=ts,
        )
        theta_scale = float(np.max(np.abs(sol.y[0])))
        np.testing.assert_allclose(m.theta(ts, w_c), sol.y[0], rtol=0, atol=RTOL * theta_scale)
        np.testing.assert_allclose(m.theta_dot(ts, w_c), sol.y[1], rtol=0, atol=RTOL * w_c)
        assert abs(sol.y[1][-1]) <= RTOL * w_c, "closed-form t_stop is where theta' = 0"


def _paper_eq3(m: ContactModel, t: np.ndarray, w_c: float, corrected: bool) -> np.ndarray:
    """Eq. (3) as printed (corrected=False) or with the sign fix derived in the README."""
    J, k, beta, tau = (
        m.total_inertia_kgm2,
        m.k_s_nm_per_rad,
        m.damping_nms_per_rad,
        m.coulomb_friction_nm,
    )
    delta = np.sqrt(complex(beta**2 - 4 * k * J))
    second_tau = tau * (beta + delta) if corrected else -tau * (beta + delta)
    theta = (
        np.exp(-t * (beta + delta) / (2 * J))
        * (-tau * (beta - delta) - 2 * J * k * w_c)
        / (2 * k * delta)
        + np.exp(-t * (beta - delta) / (2 * J)) * (second_tau + 2 * J * k * w_c) / (2 * k * delta)
        - tau / k
    )
    return np.asarray(theta.real)


@pytest.mark.parametrize("actuator", ACTUATORS)
def test_agrees_with_the_papers_eq3(actuator: str) -> None:
    m = model_for(actuator)
    w_c = 10.0
    ts = np.linspace(0.0, float(m.stop_time(np.array([w_c]))[0]), 100)
    np.testing.assert_allclose(
        m.theta(ts, w_c), _paper_eq3(m, ts, w_c, corrected=True), rtol=0, atol=1e-9
    )
    # As printed, eq. (3) does not start at theta(0) = 0 (sign of the tau_coul (beta + Delta)
    # term); the README documents the correction.
    printed = _paper_eq3(m, np.array([0.0]), w_c, corrected=False)[0]
    assert printed == pytest.approx(
        -m.coulomb_friction_nm
        / m.k_s_nm_per_rad
        * (
            1
            + m.damping_nms_per_rad
            / np.sqrt(
                complex(m.damping_nms_per_rad**2 - 4 * m.k_s_nm_per_rad * m.total_inertia_kgm2)
            )
        ).real
    )
    assert abs(printed) > 1e-3


def test_table1_regimes() -> None:
    """With Table 1 and k_s = 2 N m/rad the two geared, high-drag actuators are overdamped."""
    regimes = {a: model_for(a).regime for a in ACTUATORS}
    assert regimes == {
        "U10DD": DampingRegime.UNDERDAMPED,
        "EC60": DampingRegime.UNDERDAMPED,
        "T2822": DampingRegime.OVERDAMPED,
        "U10GB": DampingRegime.OVERDAMPED,
    }


def test_fig2_ordering_of_delay_energy_loss_and_asymptote() -> None:
    """Fig. 2: more gearing needs more energy to detect, detects later and loses more energy."""
    models = [model_for(a) for a in ACTUATORS]
    t_min = [m.min_detectable_energy() for m in models]
    assert t_min == sorted(t_min) and len(set(t_min)) == 4
    energies = np.geomspace(0.01, 10.0, 300)
    results = [m.solve(energies) for m in models]
    compared = 0
    for lower, higher in itertools.pairwise(results):
        # wherever the more geared actuator detects, the less geared one detects too, earlier,
        # having lost less energy
        both = higher.detected
        assert np.all(lower.detected[both])
        assert np.all(lower.t_r_s[both] < higher.t_r_s[both])
        assert np.all(lower.delta_e_j[both] < higher.delta_e_j[both])
        compared += int(both.sum())
    assert compared > 200
    for r in results:
        ok = r.detected
        assert np.all(np.diff(r.t_r_s[ok]) < 0), "t_r falls as T rises"


@pytest.mark.parametrize("actuator", ACTUATORS)
def test_min_detectable_energy_is_the_asymptote(actuator: str) -> None:
    m = model_for(actuator)
    t_min = m.min_detectable_energy()
    r = m.solve([t_min * (1 - 1e-7), t_min * (1 + 1e-7)])
    assert r.detected.tolist() == [False, True]
    assert r.theta_max_rad[0] == pytest.approx(m.threshold_rad, rel=1e-6)
    # at the asymptote the shaft just reaches the threshold at rest: all energy is spent
    assert r.delta_e_j[1] == pytest.approx(t_min, rel=1e-3)
    assert r.t_r_s[1] == pytest.approx(r.t_stop_s[1], rel=1e-3)


def test_no_detection_when_friction_stops_the_shaft() -> None:
    m = model_for("U10GB")
    r = m.solve([0.0, 0.5, 1.0])
    assert not r.detected.any()
    assert np.all(r.theta_max_rad < m.threshold_rad)
    assert np.isnan(r.t_r_s).all() and np.isnan(r.delta_e_j).all() and np.isnan(r.v_s_e_m_s).all()
    assert r.t_stop_s[0] == 0.0 and r.theta_max_rad[0] == 0.0


def test_impact_is_inelastic() -> None:
    m = model_for("U10DD")
    r = m.solve([1.0])
    v_t = math.sqrt(2.0 / m.shuttle_mass_kg)
    assert r.v_s_t_m_s[0] == pytest.approx(v_t)
    assert r.omega_c_rad_s[0] == pytest.approx(
        m.shuttle_mass_kg
        * m.arm_length_m
        * v_t
        / (m.actuator_inertia_kgm2 + m.shuttle_mass_kg * 0.01)
    )
    assert m.actuator_inertia_kgm2 == pytest.approx(4.47e-4 + 6.5e-5)


def test_vectorised_equals_one_at_a_time() -> None:
    m = model_for("EC60")
    energies = np.geomspace(0.01, 10, 2000)
    together = m.solve(energies)
    for i in (0, 137, 900, 1999):
        alone = m.solve(energies[i])
        for name in ("t_r_s", "delta_e_j", "v_s_e_m_s", "theta_max_rad"):
            np.testing.assert_allclose(
                getattr(together, name)[i], getattr(alone, name)[0], rtol=1e-13
            )


def test_k_d_adds_damping_and_overrides_apply() -> None:
    base = model_for("EC60")
    damped = model_for("EC60", k_d_nms_per_rad=0.1, threshold_rad=0.05, shuttle_mass_kg=1.0)
    assert damped.damping_nms_per_rad == pytest.approx(base.damping_nms_per_rad + 0.1)
    assert damped.threshold_rad == 0.05 and damped.shuttle_mass_kg == 1.0


@pytest.mark.parametrize("bad", [-1.0, float("nan"), float("inf"), [[1.0]], [1.0, -0.5]])
def test_bad_energies_are_refused(bad: object) -> None:
    with pytest.raises(ModelError, match="collision energy"):
        model_for("U10DD").solve(bad)  # type: ignore[arg-type]


def test_bad_model_parameters_are_refused() -> None:
    with pytest.raises(ModelError, match=r"ContactModel\.k_s_nm_per_rad must be finite and > 0"):
        model_for("U10DD", k_s_nm_per_rad=0.0)
    with pytest.raises(ModelError, match="arm inertia and k_d"):
        model_for("U10DD", arm_inertia_kgm2=-1.0)


@settings(max_examples=200, deadline=None)
@given(
    inertia=st.floats(1e-5, 1e-1),
    k_s=st.floats(0.1, 50.0),
    zeta=st.floats(0.01, 20.0),
    coulomb=st.floats(0.0, 0.5),
    energy=st.floats(1e-3, 50.0),
)
def test_root_and_stop_time_properties(
    inertia: float, k_s: float, zeta: float, coulomb: float, energy: float
) -> None:
    """Any physical parameters: theta(t_r) = threshold, 0 < t_r <= t_stop, theta'(t_stop) = 0."""
    J = inertia + 0.5 * 0.01
    m = ContactModel("prop", inertia, 0.5, 0.1, k_s, zeta * 2 * math.sqrt(k_s * J), coulomb, 0.1)
    r = m.solve([energy])
    w_c = float(r.omega_c_rad_s[0])
    t_stop = float(r.t_stop_s[0])
    assert t_stop > 0
    assert abs(float(m.theta_dot(t_stop, w_c))) <= 1e-9 * w_c
    assert bool(r.detected[0]) == (r.theta_max_rad[0] >= 0.1)
    if r.detected[0]:
        t_r = float(r.t_r_s[0])
        assert 0 < t_r <= t_stop * (1 + 1e-12)
        assert float(m.theta(t_r, w_c)) == pytest.approx(0.1, rel=1e-9)
        assert 0 <= r.delta_e_j[0] <= energy * (1 + 1e-12)
