"""The documentation: the site builds in strict mode, the API reference covers every module, the
README's links lead somewhere, its table of the FMU's variables is the FMU's, and the example both
pages show runs and prints what they say it prints.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
PACKAGES = (ROOT / "src" / "piezo_fmu", ROOT / "src" / "piezo_fmu_harness")
MAX_FIGURE_BYTES = 150_000
MAX_FIGURES_BYTES = 1_500_000


def test_the_site_builds_in_strict_mode_without_a_warning(tmp_path):
    # NO_MKDOCS_2_WARNING silences the Material theme's banner about its end of life, which is
    # printed outside mkdocs's logging; anything mkdocs or a plugin warns about fails the build.
    done = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
                          cwd=ROOT, capture_output=True, text=True, env={**os.environ, "NO_MKDOCS_2_WARNING": "1"})
    assert done.returncode == 0, done.stderr
    assert "WARNING" not in done.stderr, done.stderr
    assert (tmp_path / "site" / "index.html").is_file()
    for page in ("model", "core", "fmu", "simulators", "harness", "dynamics", "validation", "crosscheck",
                 "reliability", "benchmarks", "contributing", "api/model", "api/solver", "api/fmi", "api/harness"):
        assert (tmp_path / "site" / page / "index.html").is_file(), page
    reference = (tmp_path / "site" / "api" / "harness" / "index.html").read_text()
    assert 'id="piezo_fmu_harness.fmus.path"' in reference  # generated from the docstring


def module_names() -> list[str]:
    names = []
    for package in PACKAGES:
        for path in sorted(package.rglob("*.py")):
            parts = (package.name,) + path.relative_to(package).with_suffix("").parts
            if parts[-1] == "__main__":
                continue
            names.append(".".join(parts[:-1] if parts[-1] == "__init__" else parts))
    return names


@pytest.mark.parametrize("name", module_names())
def test_every_module_is_in_the_api_reference(name):
    directives = set(re.findall(r"^::: (\S+)$", "\n".join(p.read_text() for p in (DOCS / "api").glob("*.md")), re.M))
    assert name in directives, f"{name} has no '::: {name}' in docs/api/"


def test_the_readme_links_lead_to_files_of_the_repository():
    text = (ROOT / "README.md").read_text()
    targets = re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", text)
    assert targets
    missing = [t for t in targets if not t.startswith("http") and not (ROOT / t).is_file()]
    assert not missing, missing


def test_the_figures_are_small():
    sizes = {p.relative_to(ROOT): p.stat().st_size for p in DOCS.rglob("*.png")}
    assert all(size < MAX_FIGURE_BYTES for size in sizes.values()), sizes
    assert sum(sizes.values()) < MAX_FIGURES_BYTES, sum(sizes.values())
    pages = "\n".join(p.read_text() for p in DOCS.rglob("*.md"))
    unused = [str(p) for p in sizes if f"({p.relative_to('docs').as_posix()})" not in pages]
    assert not unused, f"figures no page shows: {unused}"


def fmpy_example(path: Path) -> str:
    blocks = re.findall(r"```python\n(.*?)```", path.read_text(), re.S)
    return next(block for block in blocks if "simulate_fmu" in block)


def test_the_fmpy_example_runs_and_prints_what_the_pages_say(tmp_path):
    example = fmpy_example(ROOT / "README.md")
    assert example == fmpy_example(DOCS / "index.md"), "README.md and docs/index.md show different examples"
    code_lines = [line for line in example.splitlines() if line.strip() and not line.startswith("#")]
    assert len(code_lines) <= 10
    expected = example.rstrip().splitlines()[-1].removeprefix("# ")
    environ = {key: value for key, value in os.environ.items() if key != "PIEZO_FMU"}
    done = subprocess.run([sys.executable, "-c", example], cwd=tmp_path, capture_output=True, text=True, env=environ)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == expected


def readme_variable_rows() -> list[tuple[list[str], str, list[str], list[str]]]:
    """The rows of the README's table of variables: names, causality, units, defaults."""
    section = (ROOT / "README.md").read_text().split("## The FMU's variables", 1)[1].split("\n## ", 1)[0]
    rows = []
    for line in section.splitlines():
        if not line.startswith("| `"):
            continue
        cells = [cell.strip() for cell in line.strip().strip("|").split("|")]
        names = re.findall(r"`([^`]+)`", cells[0])
        units = [unit.strip() for unit in cells[2].split(",")]
        defaults = [value.strip() for value in cells[3].split(",")] if cells[3] else []
        rows.append((names, cells[1], units, defaults))
    return rows


def test_the_readme_table_of_variables_is_the_fmus():
    from piezo_fmu.fmi.variables import VARIABLES

    table = {spec.name: spec for spec in VARIABLES}
    rows = readme_variable_rows()
    assert len(rows) >= 15
    listed = set()
    for names, causality, units, defaults in rows:
        assert len(units) == len(names), names
        assert not defaults or len(defaults) == len(names), names
        for k, name in enumerate(names):
            spec = table[name]
            assert spec.causality == causality, (name, causality)
            assert units[k] == (spec.unit if spec.type == "Real" else "-"), (name, units[k])
            if spec.causality in ("parameter", "input"):
                assert float(defaults[k]) == spec.start, (name, defaults[k])
            listed.add(name)
    assert {spec.name for spec in VARIABLES if spec.causality == "input"} <= listed
    words = {"three": 3, "four": 4, "five": 5, "six": 6, "seven": 7, "eight": 8, "nine": 9, "ten": 10}
    more = re.search(r"(\w+) more outputs", (ROOT / "README.md").read_text())
    unlisted = [spec.name for spec in VARIABLES if spec.causality == "output" and spec.name not in listed]
    assert more and words[more.group(1)] == len(unlisted), unlisted


def test_the_derived_figures_the_pages_quote_are_the_codes():
    """The constants of the nominal damper that several pages quote, computed from the code: the
    optimal-load estimate, the patch's capacitance, the contact frequency, the frequency of the main
    mass carrying the impact mass, the resonant amplitude of the main mass alone under 1 mm of base
    motion, and the random study's warm-up."""
    import math

    from piezo_fmu import Damper, Parameters
    from piezo_fmu_harness.random_response.spec import default_warmup

    nominal = Parameters()
    damper = Damper.of(nominal)
    omega_c, c_p = damper.contact_frequency, damper.barrier.C_p
    zeta = nominal.C / (2 * math.sqrt(nominal.K * nominal.M))
    carried = math.sqrt(nominal.M / (nominal.M + nominal.m))
    warmup = default_warmup({"M": nominal.M, "K": nominal.K, "C": nominal.C}, 0.1)
    quoted = {
        "README.md": [f"`sqrt(K/(M + m))` = {carried:.3f} `w_n`", f"{1e3 * 1e-3 / (2 * zeta):.0f} mm"],
        "docs/harness.md": [f"`R_opt ~ 1/(omega_c C_p)` = {1e-6 / (omega_c * c_p):.2f} MOhm",
                            f"`C_p` = {1e9 * c_p:.3f}",
                            f"`omega_c` = {omega_c:.0f}", f"`sqrt(K/(M + m)) = {carried:.3f} w_n`",
                            f"| {1e3 * 1e-3 / (2 * zeta):.1f} mm, stable", f"({warmup:.1f} s for the"],
        "docs/core.md": [f"`omega_c` ({omega_c:.0f} rad/s", f"= {1e-6 / (omega_c * c_p):.2f} MOhm"],
        "docs/model.md": [f"`w_n = {omega_c:.0f} rad/s`", f"| {1e-6 / (omega_c * c_p):.2f} MOhm |"],
    }
    for page, figures in quoted.items():
        text = (ROOT / page).read_text()
        missing = [figure for figure in figures if figure not in text]
        assert not missing, (page, missing)
