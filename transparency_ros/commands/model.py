"""``transparency model``: the paper's contact model from the command line."""

from __future__ import annotations

import argparse
import math
import sys
from typing import Any

from transparency_ros.analysis.fig2 import ModelCurve, model_curves, plot_fig2
from transparency_ros.commands.outputs import output_file
from transparency_ros.core import strict_json
from transparency_ros.core.config import load_actuators, load_drop_test
from transparency_ros.core.contact_model import ContactModel
from transparency_ros.core.errors import ModelError

EXAMPLES = """\
examples:
  transparency model --actuator U10DD --energy 0.5 --json
  transparency model --actuator T2822 --energy 0.5 1 2 5
  transparency model --curves --plot fig2.png
  transparency model --curves --actuator EC60 --arm-inertia 1e-4 --json
"""


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "model",
        help="contact model of eq. (2)-(4): detection delay and energy loss",
        description=(
            "Evaluate the paper's contact model for a drop test: the shuttle hits the arm "
            "inelastically, the virtual spring k_s deflects, and contact is detected when the "
            "deflection reaches the threshold. Prints t_r [s], Delta E [J], omega_c [rad/s], "
            "v_s,e [m/s] and whether contact is detected; --curves evaluates Fig. 2 for a range "
            "of energies."
        ),
        epilog=EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "--actuator",
        action="append",
        metavar="NAME",
        help="Table 1 actuator (repeat for several; default: all with --curves, "
        "required otherwise)",
    )
    p.add_argument(
        "--energy", type=float, nargs="+", metavar="J", help="collision energy T [J] (one or more)"
    )
    p.add_argument(
        "--curves",
        action="store_true",
        help="evaluate the energy-delay curves of Fig. 2 over --energy-range",
    )
    p.add_argument(
        "--energy-range",
        type=float,
        nargs=2,
        default=(0.01, 10.0),
        metavar=("LOW_J", "HIGH_J"),
        help="energy range of --curves (default 0.01 10)",
    )
    p.add_argument(
        "--points", type=int, default=400, help="log-spaced energies per curve (default 400)"
    )
    p.add_argument("--plot", metavar="PNG", help="with --curves: write Fig. 2a/2b to this PNG")
    p.add_argument("--json", action="store_true", help="print machine-readable JSON")
    g = p.add_argument_group("overrides of config/drop_test.yaml")
    g.add_argument(
        "--arm-inertia", type=float, metavar="KGM2", help="arm inertia added to J_r [kg m^2]"
    )
    g.add_argument("--shuttle-mass", type=float, metavar="KG", help="shuttle mass m_s [kg]")
    g.add_argument("--arm-length", type=float, metavar="M", help="arm length r [m]")
    g.add_argument("--k-s", type=float, metavar="NM_PER_RAD", help="virtual spring k_s [N m/rad]")
    g.add_argument(
        "--k-d",
        type=float,
        metavar="NMS_PER_RAD",
        help="impedance damping k_d, added to b_v [N m s/rad]",
    )
    g.add_argument("--threshold", type=float, metavar="RAD", help="detection threshold [rad]")
    g.add_argument("--actuators-file", metavar="YAML", help="use this actuators.yaml")
    g.add_argument("--drop-test-file", metavar="YAML", help="use this drop_test.yaml")
    p.set_defaults(func=run)


def _models(args: argparse.Namespace) -> list[ContactModel]:
    actuators = load_actuators(args.actuators_file)
    drop_test = load_drop_test(args.drop_test_file)
    names = args.actuator or list(actuators)
    unknown = [n for n in names if n not in actuators]
    if unknown:
        raise ModelError(f"unknown actuator(s) {unknown}; known: {', '.join(actuators)}")
    return [
        ContactModel.from_config(
            actuators[name],
            drop_test,
            arm_inertia_kgm2=args.arm_inertia,
            shuttle_mass_kg=args.shuttle_mass,
            arm_length_m=args.arm_length,
            k_s_nm_per_rad=args.k_s,
            k_d_nms_per_rad=args.k_d,
            threshold_rad=args.threshold,
        )
        for name in names
    ]


def _clean(value: float) -> float | None:
    """JSON has no NaN: quantities that do not exist (no detection) become null."""
    return None if math.isnan(value) else value


def model_summary(m: ContactModel) -> dict[str, Any]:
    return {
        "actuator": m.actuator,
        "actuator_inertia_kgm2": m.actuator_inertia_kgm2,
        "total_inertia_kgm2": m.total_inertia_kgm2,
        "shuttle_mass_kg": m.shuttle_mass_kg,
        "arm_length_m": m.arm_length_m,
        "k_s_nm_per_rad": m.k_s_nm_per_rad,
        "damping_nms_per_rad": m.damping_nms_per_rad,
        "coulomb_friction_nm": m.coulomb_friction_nm,
        "threshold_rad": m.threshold_rad,
        "damping_ratio": m.damping_ratio,
        "regime": m.regime.value,
        "min_detectable_energy_j": m.min_detectable_energy(),
    }


def _point_rows(m: ContactModel, energies: list[float]) -> list[dict[str, Any]]:
    r = m.solve(energies)
    rows = []
    for i in range(len(r.energy_j)):
        rows.append(
            {
                "energy_j": float(r.energy_j[i]),
                "detected": bool(r.detected[i]),
                "t_r_s": _clean(float(r.t_r_s[i])),
                "delta_e_j": _clean(float(r.delta_e_j[i])),
                "omega_c_rad_s": float(r.omega_c_rad_s[i]),
                "v_s_t_m_s": float(r.v_s_t_m_s[i]),
                "v_s_e_m_s": _clean(float(r.v_s_e_m_s[i])),
                "theta_max_rad": float(r.theta_max_rad[i]),
            }
        )
    return rows


def _fmt(value: float | None, scale: float = 1.0, spec: str = ".4g") -> str:
    return "-" if value is None else format(value * scale, spec)


def _run_points(models: list[ContactModel], energies: list[float], as_json: bool) -> int:
    report = [{**model_summary(m), "results": _point_rows(m, energies)} for m in models]
    if as_json:
        strict_json.dump(report[0] if len(report) == 1 else report, sys.stdout)
        return 0
    for entry in report:
        print(
            f"{entry['actuator']}: J = {entry['total_inertia_kgm2']:.4g} kg m^2, "
            f"zeta = {entry['damping_ratio']:.3f} ({entry['regime']}), "
            f"minimum detectable energy {entry['min_detectable_energy_j']:.4g} J"
        )
        print(
            f"  {'T [J]':>9} {'detected':>8} {'t_r [ms]':>9} {'dE [J]':>9} "
            f"{'w_c [rad/s]':>11} {'v_s,t [m/s]':>11} {'v_s,e [m/s]':>11}"
        )
        for row in entry["results"]:
            print(
                f"  {row['energy_j']:>9.4g} {'yes' if row['detected'] else 'no':>8} "
                f"{_fmt(row['t_r_s'], 1e3):>9} {_fmt(row['delta_e_j']):>9} "
                f"{row['omega_c_rad_s']:>11.4g} {row['v_s_t_m_s']:>11.4g} "
                f"{_fmt(row['v_s_e_m_s']):>11}"
            )
    return 0


def curves_report(curves: list[ModelCurve]) -> list[dict[str, Any]]:
    out = []
    for c in curves:
        r = c.result
        out.append(
            {
                **model_summary(c.model),
                "delta_e_slope": _clean(c.delta_e_slope),
                "energy_j": r.energy_j.tolist(),
                "t_r_s": [_clean(v) for v in r.t_r_s.tolist()],
                "delta_e_j": [_clean(v) for v in r.delta_e_j.tolist()],
            }
        )
    return out


def _run_curves(models: list[ContactModel], args: argparse.Namespace) -> int:
    low, high = args.energy_range
    curves = model_curves(models, low, high, args.points)
    if args.plot:
        path = plot_fig2(curves, args.plot)
        print(f"wrote {path}", file=sys.stderr)
    if args.json:
        strict_json.dump({"curves": curves_report(curves)}, sys.stdout, indent=None)
        return 0
    print(
        f"{'actuator':<8} {'regime':<12} {'zeta':>6} {'T_min [J]':>10} {'dE/dT':>7}  "
        f"t_r at 1 J / 5 J [ms]"
    )
    for c in curves:
        at = c.model.solve([1.0, 5.0])
        print(
            f"{c.model.actuator:<8} {c.model.regime.value:<12} {c.model.damping_ratio:>6.3f} "
            f"{c.min_detectable_energy_j:>10.4g} {c.delta_e_slope:>7.3f}  "
            f"{_fmt(_clean(float(at.t_r_s[0])), 1e3, '.3f')} / "
            f"{_fmt(_clean(float(at.t_r_s[1])), 1e3, '.3f')}"
        )
    return 0


def run(args: argparse.Namespace) -> int:
    if args.plot and not args.curves:
        raise ModelError("--plot needs --curves")
    if args.plot:
        output_file(args.plot, "--plot")
    models = _models(args)
    if args.curves:
        return _run_curves(models, args)
    if not args.energy:
        raise ModelError("give --energy J [J ...] (or --curves for the whole range)")
    if not args.actuator:
        raise ModelError("give --actuator NAME (one of: " + ", ".join(load_actuators()) + ")")
    return _run_points(models, args.energy, args.json)
