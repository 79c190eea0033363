"""A branch of periodic orbits from one seed, and the bifurcations along it (see
:mod:`piezo_fmu_harness.studies.continuation.tracer` for the method).

:func:`trace_branch` is a task of the sweep engine: it follows the branch through a seed orbit in
both directions, names the bifurcations between consecutive points, and at a period doubling
looks for the doubled branch, whose seed it returns for the caller to follow in turn.

The harness reads nothing but the FMU: it never imports the simulation core.
"""

from __future__ import annotations

import math
from dataclasses import asdict
from typing import Optional

import numpy as np

from ...fmu import Instance
from .tracer import Point, Problem, Settings, Tracer

#: A real multiplier counts as real when its imaginary part is below this.
REAL = 1e-9


def _real_product(multipliers: np.ndarray, shift: float) -> float:
    """``prod(mu_i - shift)`` over the real multipliers' signs: its sign changes when a real
    multiplier crosses ``shift`` (complex pairs give positive factors)."""
    return float(np.prod(np.real(multipliers - shift)[np.abs(np.imag(multipliers)) < REAL]))


def _unstable_pairs(multipliers: np.ndarray) -> int:
    return int(np.sum((np.abs(np.imag(multipliers)) >= REAL) & (np.abs(multipliers) > 1.0)))


def events(points: list[dict], branch: int) -> list[dict]:
    """The bifurcations between consecutive points of one branch (records of :class:`Point`
    with ``tangent_lam`` and ``multipliers`` as ``[re, im]``)."""
    found = []
    for k in range(1, len(points)):
        a, b = points[k - 1], points[k]
        ma = np.array([complex(*m) for m in a["multipliers"]])
        mb = np.array([complex(*m) for m in b["multipliers"]])

        def event(kind: str, crossing: Optional[complex], lam: float, amplitude: float) -> dict:
            return {"kind": kind, "branch": branch, "between": [k - 1, k], "lam": float(lam),
                    "amplitude": float(amplitude), "ratio_between": [a["lam"], b["lam"]],
                    "crosses_plus_one": bool(_real_product(ma, 1.0) * _real_product(mb, 1.0) < 0),
                    "crosses_minus_one": bool(_real_product(ma, -1.0) * _real_product(mb, -1.0) < 0),
                    "multiplier": None if crossing is None else [float(crossing.real), float(crossing.imag)],
                    "stable_before": a["stable"], "stable_after": b["stable"]}

        if a["tangent_lam"] * b["tangent_lam"] < 0:  # the parameter turns back
            lam, amplitude = _turning_point(points, k)
            real = [mu for mu in list(ma) + list(mb) if abs(mu.imag) < REAL] or list(ma) + list(mb)
            found.append(event("fold", min(real, key=lambda mu: abs(mu - 1.0)), lam, amplitude))
        elif _real_product(ma, 1.0) * _real_product(mb, 1.0) < 0:
            # A real multiplier crosses +1 without a turn: a branch point (symmetry breaking).
            found.append(event("branch point", min(list(mb), key=lambda mu: abs(mu - 1.0)),
                               0.5 * (a["lam"] + b["lam"]), 0.5 * (a["amplitude"] + b["amplitude"])))
        if _real_product(ma, -1.0) * _real_product(mb, -1.0) < 0:
            near = [min(ms, key=lambda mu: abs(mu + 1.0)) for ms in (ma, mb)]
            w = _crossing(abs(near[0] + 1.0), -abs(near[1] + 1.0))
            found.append(event("period doubling", near[1], *_between(a, b, w)))
        if _unstable_pairs(ma) != _unstable_pairs(mb):
            pairs = [max((mu for mu in ms if abs(mu.imag) >= REAL), key=abs, default=complex(0.0)) for ms in (ma, mb)]
            w = _crossing(abs(pairs[0]) - 1.0, abs(pairs[1]) - 1.0)
            found.append(event("Neimark-Sacker", max(pairs, key=abs), *_between(a, b, w)))
        if a["impacts"] != b["impacts"]:
            velocities = [v for v in (a["min_impact_velocity"], b["min_impact_velocity"]) if v is not None]
            grazing = event("grazing", None, 0.5 * (a["lam"] + b["lam"]), 0.5 * (a["amplitude"] + b["amplitude"]))
            grazing["impacts"] = [a["impacts"], b["impacts"]]
            grazing["min_impact_velocity"] = min(velocities) if velocities else None
            found.append(grazing)
    return found


def _crossing(before: float, after: float) -> float:
    """Where, as a fraction of the step, a quantity going from ``before`` to ``after`` (opposite
    signs) crosses zero, linearly; the middle when they do not straddle it."""
    return before / (before - after) if before * after < 0 else 0.5


def _between(a: dict, b: dict, w: float) -> tuple[float, float]:
    return a["lam"] + w * (b["lam"] - a["lam"]), a["amplitude"] + w * (b["amplitude"] - a["amplitude"])


def _turning_point(points: list[dict], k: int) -> tuple[float, float]:
    """The parameter's extremum near points ``k-1, k``: a parabola through three points in the
    arclength order, ``lam`` and the amplitude against their index."""
    j = min(max(k - 1, 1), len(points) - 2)
    lams = [points[i]["lam"] for i in (j - 1, j, j + 1)]
    amps = [points[i]["amplitude"] for i in (j - 1, j, j + 1)]
    c = np.polyfit([-1.0, 0.0, 1.0], lams, 2)
    s = -c[1] / (2 * c[0]) if c[0] != 0 else 0.0
    s = min(max(s, -1.0), 1.0)
    return float(np.polyval(c, s)), float(np.polyval(np.polyfit([-1.0, 0.0, 1.0], amps, 2), s))


def _records(points: list[Point], direction: float) -> list[dict]:
    """JSON-safe points with ``tangent_lam``, the tangent's parameter component along the branch's
    forward direction (``direction`` -1 for points found going backward)."""
    return [{**p.record(), "tangent_lam": direction * float(p.tangent[4])} for p in points]


def _end(points: list[Point], why: str, gap: float) -> str:
    """Why a branch's end stopped; a failed corrector at an orbit whose closest free approach to a
    barrier has come within 1% of the half gap is a grazing."""
    last = points[-1].measures
    clearance = last["min_free_clearance"]
    if why.startswith("the corrector failed") and clearance is not None and clearance < 0.01 * 0.5 * gap:
        return f"grazing: a free flight comes within {clearance:.3g} m of a barrier"
    return why


def trace_branch(instance: Instance, problem: dict, settings: dict, seed: dict) -> dict:
    """Follow the branch through ``seed`` (``lam``, ``state``, ``phase``, ``order``, ``depth``)
    both ways: a JSON-safe record with its points, events, the doubled branches' seeds, why each
    end stopped and the runs of ``P^n`` it took."""
    problem, settings = Problem(**problem), Settings(**settings)
    lam, state = float(seed["lam"]), np.asarray(seed["state"], float)
    length = problem.omega_and_amplitude(lam)[1]
    tracer = Tracer(instance, problem, settings, float(seed["phase"]), int(seed["order"]), length)
    start = tracer.point(tracer.unknowns(state, lam), 0, None)
    if start is not None and start.measures["section_clearance"] <= 0:
        start = tracer.rephase(start)
    if start is None:
        return {"seed": seed, "points": [], "events": [], "seeds": [], "ends": ["the seed could not be started"],
                "evaluations": tracer.map.evaluations}
    if start.tangent[4] < 0:
        start.tangent = -start.tangent
    phase = tracer.map.phase
    forward, why_forward = tracer.follow(start, 1.0, lambda p: None)
    backward, why_back = [start], "the branch closed going forward"
    if not why_forward.startswith("closed loop"):
        tracer.map.phase = phase
        backward, why_back = tracer.follow(start, -1.0, lambda p: None)
    points = _records(backward[:0:-1], -1.0) + _records(forward, 1.0)
    ends = [_end(backward, why_back, tracer.gap), _end(forward, why_forward, tracer.gap)]
    record = {"seed": seed, "points": points, "ends": ends, "evaluations": tracer.map.evaluations}
    record["events"] = events(points, 0) + [
        {"kind": "grazing", "branch": 0, "between": [index, index], "lam": points[index]["lam"],
         "amplitude": points[index]["amplitude"], "multiplier": None, "stable_before": points[index]["stable"],
         "stable_after": points[index]["stable"], "min_free_clearance": points[index]["min_free_clearance"]}
        for index, end in ((0, ends[0]), (len(points) - 1, ends[1])) if end.startswith("grazing")]
    record["seeds"] = _doubled_seeds(tracer, points, record["events"], seed) \
        if seed.get("depth", 0) < settings.doubling_depth else []
    record["evaluations"] = tracer.map.evaluations
    return record


def _doubled_seeds(tracer: Tracer, points: list[dict], found: list[dict], seed: dict) -> list[dict]:
    """At each period doubling, an orbit of twice the order near it, by Newton on ``P^(2n)`` from
    the point beyond the crossing displaced along the eigenvector of the multiplier near -1."""
    seeds = []
    for event in found:
        if event["kind"] != "period doubling":
            continue
        for index in event["between"]:
            point = points[index]
            doubled = _newton_doubled(tracer, point)
            if doubled is not None:
                seeds.append({"lam": point["lam"], "state": [float(v) for v in doubled], "phase": point["phase"],
                              "order": 2 * tracer.order, "depth": seed.get("depth", 0) + 1})
                break
    return seeds


def _newton_doubled(tracer: Tracer, point: dict) -> Optional[np.ndarray]:
    """A fixed point of ``P^(2n)`` at the point's parameter that is not one of ``P^n``."""
    lam, x = point["lam"], np.asarray(point["state"], float)
    order = 2 * tracer.order
    tracer.map.phase = point["phase"]
    scale = tracer.S
    h = 1e-6 * max(1.0, float(np.max(np.abs(x * scale))))
    image = tracer.map(x, lam, order=tracer.order)
    if image is None:
        return None
    jac = np.empty((4, 4))
    for i in range(4):
        shifted = x.copy()
        shifted[i] += h / scale[i]
        value = tracer.map(shifted, lam, order=tracer.order)
        if value is None:
            return None
        jac[:, i] = (value - image) * scale / h
    values, vectors = np.linalg.eig(jac)
    vector = np.real(vectors[:, int(np.argmin(np.abs(values + 1.0)))])
    tolerance = tracer.problem.tolerance * tracer.problem.omega_and_amplitude(lam)[1]
    for sign in (1.0, -1.0):
        z = x * scale + sign * 0.02 * max(1.0, float(np.max(np.abs(x * scale)))) * vector / np.max(np.abs(vector))
        for _ in range(12):
            y = z / scale
            fy = tracer.map(y, lam, order=order)
            if fy is None:
                break
            g = (fy - y) * scale
            if np.max(np.abs(g)) * tracer.length <= tolerance:
                single = tracer.map(y, lam, order=tracer.order)
                if single is not None and np.max(np.abs(single - y)) > 1e3 * tolerance:
                    return y
                break
            columns = np.empty((4, 4))
            for i in range(4):
                shifted = z.copy()
                shifted[i] += h
                value = tracer.map(shifted / scale, lam, order=order)
                if value is None:
                    return None
                columns[:, i] = ((value * scale - shifted) - g) / h
            z = z + np.linalg.solve(columns, -g)
    return None


def settings_dict(settings: Settings) -> dict:
    return asdict(settings)


def distance_to_branch(points: list[dict], lam: float, amplitude: float, order: int) -> float:
    """How far (relative amplitude) an orbit of ``order`` at ``lam`` lies from the branch: the
    smallest relative difference to the amplitude interpolated on a segment that spans ``lam``."""
    best = math.inf
    for a, b in zip(points, points[1:]):
        if a["order"] != order or not min(a["lam"], b["lam"]) <= lam <= max(a["lam"], b["lam"]):
            continue
        w = 0.0 if b["lam"] == a["lam"] else (lam - a["lam"]) / (b["lam"] - a["lam"])
        interpolated = a["amplitude"] + w * (b["amplitude"] - a["amplitude"])
        best = min(best, abs(interpolated - amplitude) / max(amplitude, 1e-300))
    return best
