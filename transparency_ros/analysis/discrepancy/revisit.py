"""Decisions the discovery loop (:mod:`discover`) takes again once its search has ended.

The search names one effect a round, each judged on the model of its round: an effect found
later may have been missing then, and what was named may have stood in for part of it. Two
decisions are taken again on the model the search ended with:

* :func:`rivals_again`: a shown effect against its rival (a rebound the load cell shows against
  a ringing hub spring), and a rival named in its place with the shown effect on top of it;
* :func:`still_needed`: each effect the search named, taken out and tried again by the rule
  that named it (``Discoverer._names``): one that no longer names is dropped;
* :func:`variants_again`: a named effect against its variants that hold some of its
  parameters (a band with the arm on its far flank against one whose start is fitted);
* :func:`friction_given_away`: a drift fitted with no Coulomb torque at all, or with its
  Coulomb torque off nominal beside another term, tried as the drift of its other terms and
  an offset;
* :func:`told_from_nothing`: the rule that names nothing whose 95 % interval holds its value
  of no effect, read once more on the final model (after the load cell's stage too).
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np

from transparency_ros.analysis.discrepancy.findings import Report, update_findings
from transparency_ros.analysis.discrepancy.fitting import aic, fit_cost, interval, refit, rmse
from transparency_ros.analysis.discrepancy.model import FloatArray
from transparency_ros.analysis.discrepancy.problem import hook
from transparency_ros.analysis.discrepancy.steps import ALIKE, Base, null_inside, same, total

if TYPE_CHECKING:
    from transparency_ros.analysis.discrepancy.discover import Discoverer


def rivals_again(
    loop: Discoverer,
    report: Report,
    effects: list[Any],
    params: list[FloatArray],
    floor: float,
) -> tuple[list[Any], list[FloatArray]]:
    """Each shown effect with a ``rival`` where one of the two is in the model, decided again
    on the model the search ended with: it was decided when the effect was first tried, and
    an effect the search found later may have made the two alike by its absence
    (zoo_10202: a rebound yielded to a hub spring whose held-out RMSE was 1.01 times its own;
    with the 1.6 ms sensor delay found after, the spring's was 1.26 times). Where it takes
    the other one first, the decision stands as taken, the other effects refitted with it:
    the named one's rival alone, or a rebound named that now gives way to the spring and
    comes back on top of it (zoo_10665: a rebound named before the rail friction found
    after it; on the final model the spring explains the recordings better, 0.96 times the
    rebound's RMSE, and the load cell's bounces still name a rebound on top). Where it takes
    the same one first (a spring named, and a rebound on top of it now: what is named on top
    of a spring was the search's to decide, and on zoo_10055 a rebound that took 1 % came on
    top of a true spring here), neither, or nothing, the one named stays.

    Where both are named, the rival standing for the shown effect and the shown effect on
    top of it, the two are decided again too (:func:`_rival_given_up`)."""
    for cand in loop.problem.candidates():
        rival = getattr(cand, "rival", None)
        held = [i for i, e in enumerate(effects) if e is cand or e is rival]
        if rival is None or not held:
            continue
        if len(held) == 2:
            if effects[held[0]] is rival:  # (a rival searched on top: still_needed's)
                effects, params = _rival_given_up(loop, report, (effects, params), floor, held)
            continue
        i = held[0]
        model = (effects, params)
        trial, now, new_params, _ = _added_again(loop, report, model, floor, held, cand=cand)
        taken = now[len(effects) - 1 :]
        if taken and taken[0] is not effects[i]:
            loop.progress(
                f"{effects[i].name} gives way to {' + '.join(t.name for t in taken)} on the"
                " final model"
            )
            report.findings = trial.findings
            effects, params = now, new_params
            loop._searched.discard(id(taken[0]))  # (it stands for what the recording shows)
    return effects, params


def _rival_given_up(
    loop: Discoverer,
    report: Report,
    model: tuple[list[Any], list[FloatArray]],
    floor: float,
    held: list[int],
) -> tuple[list[Any], list[FloatArray]]:
    """A rival named in a shown effect's place and the shown effect named on top of it (the
    ``model``'s effects ``held``, in that order), decided again on the final model: both taken
    out, the shown effect is added by its own rule (``_each_added``, the rival's rule read
    again). Where it is taken itself, not its rival, its fit no longer imitates the rival
    (``imitates``: a rebound needing a contact as soft as a ring's), and the rival fitted
    on top of it does not name by the search's rule (``_names``), the rival is given up:
    what it was named for, an effect found after it explains. zoo_13345 (a rebound of e 0.72
    and an inertia ×1.41): the rebound, tried first, needed a contact of 10^5.4 N/m and gave
    way to a 504 Hz spring; the drift found after took the rest, and a rebound of e 0.24 came
    on top. On the final model the rebound alone is e 0.72 off 10^6.5 N/m, the spring on top
    of it removes nothing, and the spring goes. Where the rebound still needs a soft contact
    (zoo_12409, a true 180 Hz spring: 10^5.80 N/m on the final model), both stay."""
    effects, params = model
    rival, cand = effects[held[0]], effects[held[1]]
    trial, now, new_params, err = _added_again(loop, report, model, floor, held, cand=cand)
    kept = len(effects) - 2
    taken = now[kept:]
    if not taken or taken[0] is not cand or cand.imitates(new_params[kept]):
        return effects, params
    base = Base(err, rmse(err), aic(err, total(new_params)), floor, now, new_params)
    if loop._names(loop._single(now, new_params, rival, base), base):
        return effects, params
    loop.progress(f"{rival.name} gives way to {cand.name} on the final model")
    report.findings = trial.findings
    return now, new_params


def _added_again(
    loop: Discoverer,
    report: Report,
    model: tuple[list[Any], list[FloatArray]],
    floor: float,
    out: list[int],
    *,
    cand: Any,
) -> tuple[Report, list[Any], list[FloatArray], FloatArray]:
    """The final ``model`` without its effects ``out``, ``cand`` added to it again by its own
    rule (``_each_added``: a shown effect's rival read again): (a report holding the other
    effects' findings and what was added, the effects, their parameters, the held-out
    error)."""
    effects, params = model
    keep = [j for j in range(len(effects)) if j not in out]
    others, rest = [effects[j] for j in keep], [params[j] for j in keep]
    trial = Report(report.nominal, report.split)
    trial.findings = [report.findings[j] for j in keep]  # (as ``others``)
    now, new_params, err = loop._each_added(
        trial,
        (others, rest, loop.problem.error(others, rest, True)),
        [cand],
        floor,
        loop._takes_declared,
    )
    return trial, now, new_params, err


def still_needed(
    loop: Discoverer,
    report: Report,
    effects: list[Any],
    params: list[FloatArray],
    floor: float,
) -> tuple[list[Any], list[FloatArray]]:
    """Each effect the search named alone (``_searched`` of the loop, in the order found: not
    those declared or shown, named as a pair or standing for a shown effect), taken out of
    the final model, the others refitted without it, and tried again by the rule that named
    it (``_names``, at the loop's ``keep_improvement`` where it has one). A choice made from
    the data when it was named (cogging's period, ``scan``) is kept, its fit started from its
    values in the final model, not made again on a model without it (zoo_10679: a cogging
    named at 298 periods per revolution, truth 297, removing 0.83 of the error, was scanned
    again to 306 here and removed 0.71, and was
    dropped); the others are fitted from their own starts, as in the search, and where that
    fit does not name, from the final model too, the better fit of the two on the fitting
    trials judged (zoo_12340: a 50 Hz hub spring fitted from its own start, beside a rebound
    refitted without it to e 0 against its stiffness bound, ended in another minimum and
    removed 0.27 of the error; from the final model, 0.998). One that no longer names is
    dropped with its finding, and a note says so: what it explained when it was named, an
    effect found after it explains now. The others keep the values refitted without it."""
    i = 0
    while i < len(effects):
        cand = effects[i]
        if id(cand) not in loop._searched:
            i += 1
            continue
        others, final = effects[:i] + effects[i + 1 :], params[:i] + params[i + 1 :]
        rest, result = refit(loop.problem, others, final)
        err = loop.problem.error(others, rest, True)
        base = Base(err, rmse(err), aic(err, total(rest)), floor, others, rest)
        # (a choice made from the data when it was named kept: the fit starts from its values)
        start = params[i] if getattr(cand, "scan", None) is not None else None
        step = loop._single(others, rest, cand, base, start=start)
        named = loop._names(step, base, loop.keep_improvement)
        if start is None and not named:
            # a fit from its own start, the others from their values without it, that ends
            # in another minimum: also from the final model, the better fit of the two (on
            # the fitting trials) judged
            again = loop._single(others, final, cand, base, start=params[i])
            model = [*others, cand]
            if fit_cost(loop.problem, model, again.params, None) < fit_cost(
                loop.problem, model, step.params, None
            ):
                step, named = again, loop._names(again, base, loop.keep_improvement)
        if named:
            i += 1
            continue
        loop.progress(f"{cand.name} is no longer needed on the final model: dropped")
        report.notes.append(
            f"dropped {cand.name}: named in the search, it no longer explains enough once the"
            f" effects found after it are in (share {step.gain:.2f} of the error left)"
        )
        report.findings[i : i + 1] = []
        effects, params = others, rest
        if result is not None:  # the others' values and intervals, refitted without it
            update_findings(report, effects, params, interval(result, result.x))
    return effects, params


def variants_again(
    loop: Discoverer,
    report: Report,
    effects: list[Any],
    params: list[FloatArray],
    floor: float,
) -> tuple[list[Any], list[FloatArray]]:
    """Each named effect with a variant among the candidates that holds some of its
    parameters (``same`` name, its parameters a part of the named one's: a band with the arm
    on its far flank, against one whose start in the band is fitted), decided again on the
    model the search ended with by the search's own rule (``Discoverer._choose``: of steps
    that explain the held-out recordings alike, the one with fewer parameters). The variants
    were compared on the model of the round that named the effect, where an effect found
    later may have been missing: on zoo_11934 (a band of 0.0143 rad, the arm on its far flank)
    the band on its far flank fitted 0.0137 rad but 1.06 times the held-out RMSE of a band of
    0.0190 rad with its start fitted, before the rebound the load cell shows was in the
    model; with it, the band was reported 0.0205 rad wide with the arm at 0.37 of it, the
    free travel at the strike, w (1 + start) / 2, the truth's. Where a variant is taken, every
    parameter is refitted with it, and a note says so."""
    problem = loop.problem
    for i, named in enumerate(effects):
        held = [
            c
            for c in problem.candidates()
            if c is not named
            and same(c, named)
            and set(c.param_names) < set(getattr(named, "param_names", ()))
        ]
        if not held:
            continue
        others, rest = effects[:i] + effects[i + 1 :], params[:i] + params[i + 1 :]
        err = problem.error(others, rest, True)
        base = Base(err, rmse(err), aic(err, total(rest)), floor, others, rest)
        value = dict(zip(named.param_names, params[i], strict=True))
        now = loop._single(others, rest, named, base, start=params[i])
        steps = [now] + [
            loop._single(others, rest, c, base, start=np.array([value[n] for n in c.param_names]))
            for c in held
        ]
        best = loop._choose([s for s in steps if s.meaningful and not null_inside(s)])
        if best is None or best is now or best.rmse > ALIKE * now.rmse:
            continue
        variant = best.added[0]
        k = len(others)
        # (the step's effects are the others and the variant last: the variant in its place)
        new_effects = [*others[:i], variant, *others[i:]]
        new_params = [*best.params[:i], best.params[k], *best.params[i:k]]
        before = ", ".join(f"{n} {v:.4g}" for n, v in value.items())
        after = ", ".join(
            f"{n} {v:.4g}" for n, v in zip(variant.param_names, new_params[i], strict=True)
        )
        unit = hook(problem, "unit")
        loop.progress(f"{named.name} named as its variant of fewer parameters on the final model")
        report.notes.append(
            f"{named.name} ({before}; {now.rmse:.4g} {unit} held-out RMSE) explains the"
            f" recordings as its variant with fewer parameters ({after}; {best.rmse:.4g} {unit})"
            " on the final model: named so"
        )
        x = new_params[i]
        report.findings[i] = replace(
            report.findings[i],
            parameters={n: float(v) for n, v in zip(variant.param_names, x, strict=True)}
            | variant.extra_parameters(x),
            # (of its own fit; from the joint fit below where every parameter was refitted)
            confidence_interval=dict(
                zip(variant.param_names, interval(best.result, x), strict=True)
            )
            if not best.joint
            else {},
        )
        if id(named) in loop._searched:
            loop._searched.discard(id(named))
            loop._searched.add(id(variant))
        effects, params = new_effects, new_params
        if best.joint:  # every parameter refitted with it: the findings' values and intervals
            ci, chunks, at = interval(best.result, best.result.x), [], 0
            for e, p in zip([*others, variant], best.params, strict=True):
                size = p.size if e.fittable else 0
                chunks.append(ci[at : at + size])
                at += size
            chunks = [*chunks[:i], chunks[k], *chunks[i:k]]
            update_findings(report, effects, params, [c for chunk in chunks for c in chunk])
    return effects, params


def friction_given_away(
    loop: Discoverer,
    report: Report,
    effects: list[Any],
    params: list[FloatArray],
    floor: float,
) -> tuple[list[Any], list[FloatArray]]:
    """A named effect whose fit ``gives_way``, tried on the model the search ended with as
    what it gives way to: the drift of its other terms (or none) and the effect that takes
    the Coulomb part (an offset), that one fitted with all the others. Two cases:

    * a drift whose Coulomb torque is fitted to nothing (the fit wants a torque along the
      motion, which no friction gives): the taker must be the torque the zero friction stood
      for (``takes_friction``: an offset at least the model's Coulomb torque);
    * a drift whose Coulomb torque is off nominal beside another term that drifted, its 95 %
      interval without the nominal value: where the arm turns one way the two are the same
      torque, and the search compared an offset with a Coulomb drift alone (``yields_to``),
      not with the Coulomb part of a drift of several terms (zoo_12193, zoo_12133: a viscous
      drift and an offset named as a viscous drift with the Coulomb torque x2.9 and x3.3).

    In the second case the taker is compared with the drift held to the terms that drifted,
    its Coulomb term among them: terms left free within ``DRIFT_MIN`` of nominal, which the
    drift's own rule does not name, buy fit from what the model misses elsewhere (zoo_12329:
    an offset of 0.098 N m named as a drift of the Coulomb torque x0.61 beside an inertia
    x0.96 and a viscous term x1.00, which fitted the held-out recordings 1.06 times better
    than the offset; the Coulomb term alone and the offset fitted them to eight digits alike).

    Taken, with a note, where the model then explains the held-out recordings alike
    (``ALIKE``: with no more parameters, where ``steps.choose`` takes the simpler of two
    alike), the taker is meaningful and its interval excludes its null; otherwise the drift
    stays. Where the taker is named already, the Coulomb part is given to it: the drift held
    to its other terms and every parameter refitted, taken where alike (zoo_11839: an offset
    of -0.029 N m named beside an inertia drift with no Coulomb torque, -0.063 hidden).
    Where the arm turns one way through its recordings, the two are the same torque; where
    it turns back or comes to rest, the fit tells them apart. On the final model, not in the
    search: there a Coulomb torque of nothing also stands in for an effect found later
    (zoo_11463: for a hub spring; an offset named in its place stayed named at -0.001 N m).
    On zoo_11463's final model the offset fitted in its place is 0.23 of the Coulomb torque
    (refused); on zoo_11801 and zoo_11829, each hiding an offset beside a drift, 2.3 and 3.5
    times it."""
    hit = next(
        (
            (i, way)
            for i, (e, p) in enumerate(zip(effects, params, strict=True))
            if (way := getattr(e, "gives_way", lambda _p: None)(p)) is not None
        ),
        None,
    )
    taker = None if hit is None else _candidate(loop, hit[1].taker)
    if hit is None or taker is None:
        return effects, params
    i, way = hit
    kept, start, whole = way.kept, way.start, way.whole
    problem, drift, finding = loop.problem, effects[i], report.findings[i]
    if not whole:  # the Coulomb part told from its nominal value, or nothing to give
        lo, hi = finding.confidence_interval.get(way.term, (way.null, way.null))
        if lo <= way.null <= hi:
            return effects, params
    coulomb = finding.parameters.get(way.term, float("nan"))
    before = rmse(problem.error(effects, params, True))
    smaller = None if whole else getattr(drift, "reduced", lambda _p: None)(params[i])
    if smaller is not None:  # compared with the drift of the terms that drifted (see above)
        rest, rest_params = effects[:i] + effects[i + 1 :], params[:i] + params[i + 1 :]
        err = problem.error(rest, rest_params, True)
        base = Base(err, rmse(err), aic(err, total(rest_params)), floor, rest, rest_params)
        before = loop._single(rest, rest_params, smaller[0], base, start=smaller[1]).rmse
    # the drift held to the terms that drifted, in its place (or gone where none did)
    instead = [] if kept is None else [kept]
    held = effects[:i] + instead + effects[i + 1 :]
    held_params = params[:i] + ([] if kept is None else [start]) + params[i + 1 :]
    findings = report.findings[:i] + report.findings[i + 1 :]
    if kept is not None:  # the drift's finding, of the terms that drifted
        findings.insert(
            i,
            replace(
                finding,
                parameters={n: float(v) for n, v in zip(kept.param_names, start, strict=True)}
                | kept.extra_parameters(start),
                confidence_interval={n: finding.confidence_interval[n] for n in kept.param_names},
            ),
        )
    if any(same(taker, e) for e in effects):  # named already: the Coulomb part given to it
        new_params, result = refit(problem, held, held_params)
        after = rmse(problem.error(held, new_params, True))
        if after > ALIKE * before:
            return effects, params
        new_effects = held
    else:
        err = problem.error(held, held_params, True)
        base = Base(err, rmse(err), aic(err, total(held_params)), floor, held, held_params)
        step = loop._single(held, held_params, taker, base)
        if not (
            step.rmse <= ALIKE * before
            and step.meaningful
            and not null_inside(step)
            and (not whole or getattr(taker, "takes_friction", lambda _p: True)(step.params[-1]))
        ):
            return effects, params
        findings.append(loop._finding(taker, step, base, base.rmse, step.rmse))
        new_effects, new_params, after = [*held, taker], step.params, step.rmse
        result = step.result if step.joint else None
    unit = hook(problem, "unit")
    fitted = "no Coulomb torque" if whole else f"its Coulomb torque x{coulomb:.3g}"
    held_to = "" if smaller is None else f"held to {', '.join(smaller[0].param_names)}: "
    loop.progress(f"{drift.name} with {fitted} gives way to {taker.name}")
    report.findings = findings
    report.notes.append(
        f"{drift.name} fitted with {fitted} ({held_to}{before:.4g} {unit} held-out RMSE) explains"
        f" the recordings as {taker.name}"
        + ("" if kept is None else f" beside the drift of {', '.join(kept.param_names)}")
        + f" does ({after:.4g} {unit}): named so, the Coulomb torque at its nominal value"
    )
    if result is not None:  # every parameter refitted: the findings' values and intervals
        update_findings(report, new_effects, new_params, interval(result, result.x))
    return new_effects, new_params


def _candidate(loop: Discoverer, name: str) -> Any:
    """The problem's candidate called ``name`` (None where it has none)."""
    return next((c for c in loop.problem.candidates() if c.name == name), None)


def told_from_nothing(
    loop: Discoverer,
    report: Report,
    effects: list[Any],
    params: list[FloatArray],
    held_err: FloatArray,
) -> tuple[list[Any], list[FloatArray], FloatArray]:
    """The rule that names nothing whose 95 % interval holds its value of no effect
    (``null_inside``), read once more on the final model: an effect named beside others
    (a pair, whose members the revisit does not take out one by one) may have been
    refitted to nothing by what was named after it. On zoo_12711 (a b_v drift x1.66, the
    shuttle's weight) no single effect was named, the pair of the drift and an offset
    was, the offset holding the weight; the weight was then named (``stood_in``) and the
    offset refitted to 0.0001 N m (95 % -0.0004 to 0.0006), and was still reported. Each
    such effect is dropped with a note, the others refitted without it; effects named
    for what the recording declares or shows (a shuttle's weight, a rebound the load
    cell shows) are not judged by a fit and stay. The intervals are the fit's, before
    they are widened for the model's own error; one the held-out data still need (without
    it, refitted, their RMSE more than ALIKE times higher) stays."""
    i = 0
    while i < len(effects):
        effect = effects[i]
        null = getattr(effect, "null", None)
        ci = report.findings[i].confidence_interval
        if (
            null is None
            or not effect.fittable
            or getattr(effect, "declared", False)
            or getattr(effect, "shown", False)
            or not all(name in ci for name in effect.param_names)
            or not all(
                math.isnan(z) or ci[name][0] <= z <= ci[name][1]
                for name, z in zip(effect.param_names, null, strict=True)
            )
        ):
            i += 1
            continue
        others, rest = effects[:i] + effects[i + 1 :], params[:i] + params[i + 1 :]
        rest, result = refit(loop.problem, others, rest)
        without = loop.problem.error(others, rest, True)
        if rmse(without) > ALIKE * rmse(held_err):  # (the held-out data still need it)
            i += 1
            continue
        loop.progress(f"{effect.name} is told from nothing on the final model: dropped")
        report.notes.append(
            f"dropped {effect.name}: on the final model its 95 % interval holds its value"
            " of no effect ("
            + ", ".join(
                f"{name} {params[i][k]:.4g} ({ci[name][0]:.3g} to {ci[name][1]:.3g})"
                for k, name in enumerate(effect.param_names)
            )
            + ")"
        )
        report.findings[i : i + 1] = []
        effects, params, held_err = others, rest, without
        if result is not None:
            update_findings(report, effects, params, interval(result, result.x))
        i = 0
    return effects, params, held_err
