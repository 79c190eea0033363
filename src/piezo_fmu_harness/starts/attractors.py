"""The attractors of a study of many starts, as records: one list for the study, shares with their
confidence intervals, the uncertainty of a basin map's boundary, and names that keep across a band.

The starts are marched elsewhere (the batch engine, in chunks of the sweep engine); each chunk
reports its starts' labels and the attractors it met, described as JSON records (``kind`` "orbit",
"no impacts", or, per start, a motion that is not periodic with its measures). Here they become
one list per drive (``group``):

- two orbits are the same attractor when their orders, contact onsets per period and section
  states agree (a point of one within :data:`SAME` of ``Y`` of a point of the other): an
  asymmetric orbit and its mirror image stay two attractors;
- the motion without impacts is one attractor per drive (the family where the impact mass rests);
- the starts that reach no orbit within the budget of periods are **undecided**, never
  folded into an attractor, unless the drive's survival curve shows that what is left persists
  (:func:`piezo_fmu_harness.starts.transients.escape`: a plateau, the transient died out, the
  curve flat at its end). Then a start is **chaotic** when its largest Lyapunov exponent is positive
  with a 95% interval that excludes 0, **quasi-periodic** when the interval holds 0 (or the exponent
  is within :data:`NEAR_ZERO` of it) and its section's spectrum is a few lines (line share at least
  :data:`LINES`); any other stays undecided. Each is one record per drive (``kind`` "chaotic",
  "quasi-periodic" or "undecided"), with the median of its starts' measures; an undecided record's
  ``motion`` says "converging" when that median exponent's interval lies below 0. Two chaotic
  motions at one frequency are not told apart.

**Shares** are the fractions of the starts that end on each attractor, with the 95% Wilson score
interval of a binomial proportion (for a grid of starts, as if its cells were a random sample).
**The boundary** of a basin map: the fraction of cells with a neighbour on another attractor, and
the basin entropy of Daza et al. (2016): the mean Gibbs entropy of the attractors in boxes of
``box x box`` cells (``S_b``) and over the boxes that hold more than one (``S_bb``; above
``ln 2`` the boundary is fractal).

The harness reads nothing but the FMU here: this module handles records only.
"""

from __future__ import annotations

import math

import numpy as np

from ..wording import per_cycle
from .transients import counts, escape

#: Two orbit records of one drive are the same attractor when a section state of one lies within
#: this many ``Y`` of one of the other's (the batch engine's orbits are within 1e-6 Y of exact).
SAME = 1e-4
#: z of a two-sided 95% interval.
Z95 = 1.959963984540054
#: The kinds of record of the starts that are on no orbit.
NOT_PERIODIC = ("chaotic", "quasi-periodic", "undecided")
#: An exponent (1/period) this close to 0 is 0 for a quasi-periodic motion ...
NEAR_ZERO = 0.005
#: ... whose section's spectrum holds at least this share of its variance in a few lines.
LINES = 0.9


def wilson(count: int, total: int, z: float = Z95) -> tuple[float, float]:
    """The Wilson score interval of the proportion ``count / total``."""
    if total == 0:
        return math.nan, math.nan
    p = count / total
    denominator = 1.0 + z * z / total
    centre = (p + z * z / (2 * total)) / denominator
    half = z * math.sqrt(p * (1 - p) / total + z * z / (4 * total * total)) / denominator
    return max(0.0, centre - half), min(1.0, centre + half)


def _scaled_gap(a: list, b: list, omega: float) -> float:
    scale = np.array([1.0, 1.0 / omega, 1.0, 1.0 / omega])
    a, b = np.array(a, dtype=float), np.array(b, dtype=float)
    gaps = np.abs((a[:, None, :] - b[None, :, :]) * scale)
    return float(np.nanmax(gaps, axis=2).min())


def same(a: dict, b: dict, omega: float, amplitude: float) -> bool:
    """Whether two attractor records of one drive (``omega`` rad/s, ``Y`` m) are one attractor."""
    if a["group"] != b["group"] or a["kind"] != b["kind"]:
        return False
    if a["kind"] != "orbit":  # one motion without impacts, one of each kind on no orbit, per drive
        return True
    return (a["order"] == b["order"] and sorted(a["impacts"]) == sorted(b["impacts"])
            and _scaled_gap(a["sections"], b["sections"], omega) <= SAME * amplitude)


def merge(chunks: list[dict], drives: list[tuple[float, float]]) -> tuple[list[dict], dict[int, dict]]:
    """One list of attractors from the chunks' results, and each start's record by its index with
    ``attractor`` (the index into that list) added. ``drives``: ``(omega, Y)`` of each group.

    A chunk is ``{"starts": [{"index", "group", "label", "periods", ...}], "attractors": [...]}``
    (label -1: undecided at the budget, with its measures; -2: set aside by the engine). The
    undecided starts of a drive are judged together (see the module's text); each start's record
    gains its ``motion``.
    """
    found: list[dict] = []
    starts: dict[int, dict] = {}

    def place(record: dict) -> int:
        omega, amplitude = drives[record["group"]]
        for k, other in enumerate(found):
            if same(other, record, omega, amplitude):
                return k
        found.append({**record})
        return len(found) - 1

    pending: list[dict] = []
    for chunk in chunks:
        local = [place(record) for record in chunk["attractors"]]
        for record in chunk["starts"]:
            if record["label"] >= 0:
                starts[record["index"]] = {**record, "attractor": local[record["label"]], "motion": "periodic"}
            elif record["label"] == -1:
                pending.append(record)
            else:
                starts[record["index"]] = {**record, "attractor": place({"kind": "set aside", "group": record["group"]}),
                                           "motion": "set aside"}
    fits = {}
    for record in pending:
        group = record["group"]
        if group not in fits:
            fits[group] = survival_fit([r for r in chunk_starts(chunks) if r["group"] == group])
        motion = verdict(record, fits[group])
        kind_ = motion if motion in NOT_PERIODIC else "undecided"
        starts[record["index"]] = {**record, "attractor": place({"kind": kind_, "group": group}), "motion": motion}
    _not_periodic_measures(found, starts, fits)
    return found, starts


def chunk_starts(chunks: list[dict]):
    for chunk in chunks:
        yield from chunk["starts"]


def survival_fit(records: list[dict]):
    """The fit of the survival curve (:func:`~.transients.escape`) of one drive's start records
    (``label``, ``periods``; the set aside ones left out), or None when none was resolved late
    enough to need one: no start undecided."""
    counted = [r for r in records if r["label"] != -2]
    undecided = [r["periods"] for r in counted if r["label"] < 0]
    if not undecided:
        return None
    budget = max(undecided)
    return escape([min(r["periods"], budget) for r in counted], [r["label"] >= 0 for r in counted], budget)


def verdict(record: dict, fit) -> str:
    """What an undecided start is, given its drive's survival fit: "chaotic", "quasi-periodic",
    "undecided (converging)" (its exponent's interval below 0) or "undecided"."""
    low, high, value = record.get("exponent_low"), record.get("exponent_high"), record.get("exponent")
    if high is not None and high < 0:
        return "undecided (converging)"
    if fit is None or not fit.persists or value is None:
        return "undecided"
    if low is not None and low > 0:
        return "chaotic"
    near = abs(value) <= NEAR_ZERO or (low is not None and low <= 0 <= high)
    if near and (record.get("line_share") or 0.0) >= LINES:
        return "quasi-periodic"
    return "undecided"


def _not_periodic_measures(found: list[dict], starts: dict, fits: dict) -> None:
    """The median measures of the starts of each record on no orbit, the drive's survival fit, and
    the record's ``motion``."""
    for k, attractor in enumerate(found):
        if attractor["kind"] not in NOT_PERIODIC:
            continue
        members = [r for r in starts.values() if r["attractor"] == k]
        for name in ("amplitude", "amplitude_min", "amplitude_max", "impacts_per_cycle", "exponent", "exponent_low",
                     "exponent_high", "modulation", "line_share"):
            values = [r[name] for r in members if r.get(name) is not None]
            attractor[name] = float(np.median(values)) if values else None
        fit = fits.get(attractor["group"])
        attractor["transients"] = counts(fit) if fit is not None else None
        if attractor["kind"] == "undecided":
            converging = attractor["exponent_high"] is not None and attractor["exponent_high"] < 0
            attractor["motion"] = "undecided (converging)" if converging else "undecided"
        else:
            attractor["motion"] = attractor["kind"]


def shares(found: list[dict], starts: dict, group: int) -> list[dict]:
    """The attractors of ``group`` with ``starts`` (count), ``share`` and ``share_low``/``share_high``
    (95% Wilson interval), by decreasing share."""
    members = [r for r in starts.values() if r["group"] == group]
    total = len(members)
    rows = []
    for k, attractor in enumerate(found):
        if attractor["group"] != group:
            continue
        count = sum(1 for r in members if r["attractor"] == k)
        low, high = wilson(count, total)
        rows.append({**attractor, "id": k, "starts": count, "share": count / total if total else math.nan,
                     "share_low": low, "share_high": high})
    return sorted(rows, key=lambda row: -row["starts"])


def boundary(labels: np.ndarray, box: int = 5) -> dict:
    """How uncertain a basin map's boundary is (see the module's text): ``boundary_fraction``,
    ``basin_entropy`` (``S_b``), ``boundary_basin_entropy`` (``S_bb``), and the ``box`` size."""
    labels = np.asarray(labels)
    differs = np.zeros(labels.shape, bool)
    differs[1:, :] |= labels[1:, :] != labels[:-1, :]
    differs[:-1, :] |= labels[:-1, :] != labels[1:, :]
    differs[:, 1:] |= labels[:, 1:] != labels[:, :-1]
    differs[:, :-1] |= labels[:, :-1] != labels[:, 1:]
    rows, cols = labels.shape[0] // box, labels.shape[1] // box
    entropies = []
    for i in range(rows):
        for j in range(cols):
            cell = labels[i * box:(i + 1) * box, j * box:(j + 1) * box].ravel()
            _, counts = np.unique(cell, return_counts=True)
            p = counts / counts.sum()
            entropies.append(float(-(p * np.log(p)).sum()))
    entropies = np.array(entropies)
    mixed = entropies > 0
    return {"boundary_fraction": float(differs.mean()), "box": box,
            "basin_entropy": float(entropies.mean()) if entropies.size else math.nan,
            "boundary_basin_entropy": float(entropies[mixed].mean()) if mixed.any() else 0.0,
            "boxes": int(entropies.size), "boundary_boxes": int(mixed.sum())}


def base_name(attractor: dict) -> str:
    """The name of an attractor's kind: "order n, k impacts/cycle", "no impacts", or the class of a
    motion that is not periodic."""
    if attractor["kind"] == "orbit":
        return f"order {attractor['order']}, {per_cycle(attractor['impacts_per_cycle'])}"
    if attractor["kind"] in ("chaotic", "quasi-periodic"):
        return f"{attractor['kind']} (persists)"
    return attractor["kind"]


def _signature(attractor: dict, omega: float) -> np.ndarray:
    """What a track of attractors is followed by from one frequency to the next: an orbit's section
    states (scaled to metres, sorted), else its amplitude."""
    if attractor["kind"] == "orbit":
        scale = np.array([1.0, 1.0 / omega, 1.0, 1.0 / omega])
        points = np.array(attractor["sections"], dtype=float) * scale
        return points[np.lexsort(points.T[::-1])].ravel()
    return np.array([attractor.get("amplitude") or 0.0])


def track_names(found: list[dict], groups: list[int], omegas: list[float]) -> list[str]:
    """A name for each attractor that keeps across the drives ``groups`` (in band order, at the
    frequencies ``omegas``): each kind's base name (:func:`base_name`), and for the second and later
    attractors of one kind ``#2``, ``#3`` (an orbit and its mirror image, or two branches); an
    attractor takes the name of the previous frequency's of its kind whose section states (or
    amplitude) lie nearest to its own."""
    names = [""] * len(found)
    last: dict[str, dict[str, np.ndarray]] = {}  # base name -> track name -> its latest signature
    for group, omega in zip(groups, omegas):
        by_kind: dict[str, list[int]] = {}
        for k, attractor in enumerate(found):
            if attractor["group"] == group:
                by_kind.setdefault(base_name(attractor), []).append(k)
        for base, members in by_kind.items():
            tracks = last.setdefault(base, {})
            signatures = {k: _signature(found[k], omega) for k in members}
            pairs = sorted((float(np.abs(signatures[k] - sig).max()) if sig.shape == signatures[k].shape else np.inf,
                            k, name) for k in members for name, sig in tracks.items())
            taken: dict[int, str] = {}
            for _, k, name in pairs:
                if k not in taken and name not in taken.values():
                    taken[k] = name
            for k in sorted(members):
                if k not in taken:
                    used = set(tracks) | set(taken.values())
                    taken[k] = base if base not in used else next(f"{base} #{i}" for i in range(2, len(used) + 3)
                                                                  if f"{base} #{i}" not in used)
            for k, name in taken.items():
                names[k] = name
                tracks[name] = signatures[k]
    return names
