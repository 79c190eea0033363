"""The report of ``piezo-fmu optimize`` (:mod:`piezo_fmu_harness.studies.optimize.search`): ``report.json``,
``report.md``, ``evaluations.csv`` and ``convergence.png``.

This module never imports the simulation core.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import numpy as np

from ...drawing import new_figure, save_png
from ...store import PointStore
from ...wording import counted
from .search import EVALUATIONS_FILE, Problem


#: The units of an evaluation's measures (``evaluations.csv``).
MEASURE_UNITS = {"DI": "m/s", "DI_ls": "m/s", "V_rms": "V", "amplitude": "m", "amplitude_down": "m",
                 "amplitude_without": "m", "power": "W", "rms_with": "m", "rms_without": "m",
                 "impacts_per_second": "1/s"}


def write_report(report: dict, problem: Problem, folder: Path, model) -> list[Path]:
    """``report.json``, ``report.md``, ``evaluations.csv`` and ``convergence.png``."""
    from ...datasets import csv_frame

    folder = Path(folder)
    (folder / "report.json").write_text(json.dumps(report, indent=2) + "\n")
    (folder / "report.md").write_text("\n".join(report_lines(report, problem, model)) + "\n")
    records = list(PointStore(folder, EVALUATIONS_FILE).load().values())
    import pandas

    rows = [{"index": r["index"], "phase": r["phase"], **dict(zip(problem.names, r["x"])), "objective": r["objective"],
             **{f"term_{k}": v for k, v in (r.get("terms") or {}).items()},
             **{f"measure_{k}": v for k, v in (r.get("measures") or {}).items()}, "status": r["status"],
             "seconds": r["seconds"]} for r in records]
    units = {**{name: model.units.get(name) for name in problem.names}, "seconds": "s",
             **{f"measure_{k}": unit for k, unit in MEASURE_UNITS.items()}}
    csv_frame(pandas.DataFrame(rows), units).to_csv(folder / "evaluations.csv", index=False)
    figure = convergence_figure(records, report, folder / "convergence.png")
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
             *(spectrum_lines(problem.random, optimum) if problem.random else []),
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
    if problem.objective == "random":
        return "w_ratio RMS_with / RMS_without - w_power P_mean / P_ref"
    return "w_amplitude peak_with / peak_without + w_transmissibility peak / Y - w_power P_mean / P_ref"


def spectrum_lines(spec: dict, optimum: dict) -> list[str]:
    """Under the random objective: the excitation and the realizations every design was marched on,
    the optimum's ratio with its interval, and how to check it on other realizations."""
    source, measures = spec["source"], optimum["measures"]
    level = f" of level {spec['levels'][0]:g} (m/s^2)^2/Hz" if spec["levels"] else ""
    lines = [f"- excitation: {source.get('name', source['kind'])}{level}; realizations 0-{spec['realizations'] - 1} "
             f"of seed {spec['seed']} for every design (common random numbers), {spec['warmup']:.4g} s of warm-up + "
             f"{spec['duration']:.4g} s, step {spec['step']:g} s"]
    if measures.get("ratio") is not None:
        interval = (f" (95% interval {measures['ratio_low']:.4g}-{measures['ratio_high']:.4g})"
                    if measures.get("ratio_low") is not None else "")
        settings = " ".join([f"--set {name}={value!r}" for name, value in optimum["x"].items()]
                            + ([f"--load {spec['values']['R_load']!r}"] if "R_load" not in optimum["x"] else []))
        lines += [f"- the optimum's RMS ratio {measures['ratio']:.4g}{interval}: {1e3 * measures['rms_with']:.4g} mm "
                  f"with the damper, {1e3 * measures['rms_without']:.4g} mm without; {1e3 * measures['power']:.4g} mW "
                  f"harvested, {measures['impacts_per_second']:.3g} impacts/s",
                  "- the search chose it on these realizations, whose scatter favours it; check it on others: "
                  f"`piezo-fmu random {settings} --seed {spec['seed'] + 1}` (with this command's other --set and its "
                  "excitation options)"]
    return lines

def convergence_figure(records: list[dict], report: dict, path: Path) -> Path:
    """``convergence.png``: the objective of every evaluation of the search in order, the best so
    far, and the best point of the grid of the same budget."""
    search = sorted((r for r in records if r.get("phase") == "search"), key=lambda r: r["index"])
    values = np.array([r["objective"] if r["objective"] is not None else np.nan for r in search], float)
    values[~np.isfinite(values)] = np.nan
    fig, ax = new_figure((7.5, 4.2))
    ax.plot(np.arange(1, len(values) + 1), values, ".", ms=4, color="C0", alpha=0.6, label="evaluations")
    ax.plot(np.arange(1, len(values) + 1), np.fmin.accumulate(np.where(np.isnan(values), np.inf, values)),
            color="C3", lw=1.5, label="best so far")
    grid = report.get("grid")
    if grid and grid.get("best"):
        ax.axhline(grid["best"]["objective"], color="k", ls="--", lw=1.0,
                   label=f"best of the grid of the same budget ({counted(grid['evaluations'], 'point')})")
    ax.set_xlabel("evaluation (differential evolution, then its polish)")
    ax.set_ylabel("objective J (minimised)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    ax.set_title(f"Optimisation, {report['objective']} objective: {report['search']['evaluations']} evaluations, "
                 f"{report['search']['wall_s']:.1f} s", fontsize=9)
    return save_png(fig, path)
