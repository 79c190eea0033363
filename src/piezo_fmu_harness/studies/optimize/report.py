"""The report of ``piezo-fmu optimize`` (:mod:`piezo_fmu_harness.optimize`): ``report.json``,
``report.md``, ``evaluations.csv`` and ``convergence.png``.

The harness reads nothing but the FMU: it never imports the simulation core.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

from .optimize import EVALUATIONS_FILE, Problem
from .store import PointStore


def write_report(report: dict, problem: Problem, folder: Path, model) -> list[Path]:
    """``report.json``, ``report.md``, ``evaluations.csv`` and ``convergence.png``."""
    from . import curves

    folder = Path(folder)
    (folder / "report.json").write_text(json.dumps(report, indent=2) + "\n")
    (folder / "report.md").write_text("\n".join(report_lines(report, problem, model)) + "\n")
    records = list(PointStore(folder, EVALUATIONS_FILE).load().values())
    import pandas

    rows = [{"index": r["index"], "phase": r["phase"], **dict(zip(problem.names, r["x"])), "objective": r["objective"],
             **{f"term_{k}": v for k, v in (r.get("terms") or {}).items()},
             **{f"measure_{k}": v for k, v in (r.get("measures") or {}).items()}, "status": r["status"],
             "seconds": r["seconds"]} for r in records]
    pandas.DataFrame(rows).to_csv(folder / "evaluations.csv", index=False)
    figure = curves.convergence_figure(records, report, folder / "convergence.png")
    return [folder / "report.json", folder / "report.md", folder / "evaluations.csv", figure]


def report_lines(report: dict, problem: Problem, model) -> list[str]:
    """The report as Markdown lines (SI units)."""
    def show(x: dict) -> str:
        return ", ".join(f"{name} = {value:.6g} {model.parameters[name].unit or ''}".rstrip() for name, value in x.items())

    optimum, search = report["optimum"], report["search"]
    weights = ", ".join(f"{k} {v:g}" for k, v in report["weights"].items())
    references = ", ".join(f"{k} = {v:.6g}" for k, v in report["references"].items())
    lines = [f"# Optimisation: {report['objective']} objective", "",
             f"Minimised J = {_formula(problem)}; weights {weights}; references (SI) {references}.", "",
             f"- optimum: {show(optimum['x'])}: J = {optimum['objective']:.6g}",
             "- terms: " + ", ".join(f"{k} {_number(v)}" for k, v in (optimum["terms"] or {}).items()),
             f"- reference design: {show(report['reference_design']['x'])}: J = "
             f"{report['reference_design']['objective']:.6g}",
             f"- search: {search['evaluations']} evaluations ({search['unique_evaluations']} distinct designs), "
             f"{search['generations']} generations, {search['wall_s']:.1f} s wall; {search['message']}"]
    grid = report.get("grid")
    if grid:
        if grid["best"]:
            lines.append(f"- grid of the same budget ({grid['points_per_axis']} per axis, {grid['evaluations']} "
                         f"evaluations): best {show(grid['best']['x'])}: J = {grid['best']['objective']:.6g}; the "
                         f"optimiser {'matches or beats it' if grid['optimizer_matches_or_beats_grid'] else 'does not beat it'}")
        else:
            lines.append("- grid of the same budget: every grid point was rejected by the FMU")
    sensitivity = report["sensitivity"]
    lines += ["", f"Sensitivity at the optimum (one parameter at a time, +-{100 * sensitivity['fraction_of_range']:g}% "
                  "of its range):", "", "| parameter | at | step to | J change | step to | J change |",
              "|---|---|---|---|---|---|"]
    for row in sensitivity["parameters"]:
        lines.append(f"| {row['name']} | {row['at']:.6g} | {row['minus']:.6g} | {_signed(row['change_minus'])} | "
                     f"{row['plus']:.6g} | {_signed(row['change_plus'])} |")
    return lines


def _signed(number: Optional[float]) -> str:
    return "n/a" if number is None else f"{number:+.4g}"


def _number(number: Optional[float]) -> str:
    return "n/a" if number is None else f"{number:.6g}"


def _formula(problem: Problem) -> str:
    if problem.objective == "perfectibility":
        return f"-100 (w_DI {problem.damping} / DI_ref + w_V V_rms / V_rms_ref)"
    return "w_amplitude peak_with / peak_without + w_transmissibility peak / Y - w_power P_mean / P_ref"
