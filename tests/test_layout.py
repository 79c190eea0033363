"""The shape of the code: the physics apart from the numerics, and both apart from FMI.

- Imports run one way: ``piezo_fmu.build`` may import the FMI layer, ``piezo_fmu.fmi`` the solver and
  the model, the solver the model, and the model neither; the harness never imports the core, but
  for the studies of many starts (basins, fractions, the bifurcation diagram), which import the
  batch engine ``piezo_fmu.solver.batch`` and nothing else of it.
- ``piezo_fmu.fmi`` holds only what ships inside the FMUs: every module there is a slave
  script or lies under the FMUs' ``resources/``, and what builds the FMUs is in ``piezo_fmu.build``.
- No import cycle between modules, inside the package or the harness (lazy imports in functions
  count too).
- No module over 400 lines, no class over 250.
- No file of the project points at the team's folder beside the clone (``..`` then ``shared``): a
  user's clone has no such folder.
- The harness is arranged by study: each study is a module or package under
  ``piezo_fmu_harness.studies``; the studies never import each other, and the infrastructure (the
  rest of the package) never imports a study; the CLI only collects the studies' subcommands.
"""

from __future__ import annotations

import ast
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "src" / "piezo_fmu"
HARNESS = ROOT / "src" / "piezo_fmu_harness"
MAX_MODULE_LINES = 400
MAX_CLASS_LINES = 250
LAYERS = {"model": 0, "solver": 1, "fmi": 2, "build": 3}


def module_name(path: Path) -> str:
    if PACKAGE in path.parents:
        parts = ("piezo_fmu",) + path.relative_to(PACKAGE).with_suffix("").parts
    else:
        parts = ("piezo_fmu_harness",) + path.relative_to(HARNESS).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports(path: Path) -> set[str]:
    """The modules ``path`` imports anywhere in it, resolved to absolute names."""
    name = module_name(path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")
                anchor = anchor[:len(anchor) - node.level + 1]
                base = ".".join(anchor + ([base] if base else []))
            found.add(base)
            found.update(f"{base}.{alias.name}" for alias in node.names)
    return found


def sources(folder: Path) -> list[Path]:
    return sorted(p for p in folder.rglob("*.py") if "__pycache__" not in p.parts)


def layer(module: str) -> int | None:
    parts = module.split(".")
    return LAYERS.get(parts[1]) if len(parts) > 1 and parts[0] == "piezo_fmu" else None


@pytest.mark.parametrize("path", sources(PACKAGE), ids=lambda p: str(p.relative_to(PACKAGE)))
def test_imports_run_one_way_fmi_then_solver_then_model(path):
    own = layer(module_name(path))
    if own is None:
        return  # the package's __init__ re-exports the layers below FMI
    upward = sorted(m for m in imports(path) if (other := layer(m)) is not None and other > own)
    assert not upward, f"{path.name} ({module_name(path)}) imports from a layer above it: {upward}"


#: The studies that march on the core's batch engine (those of many starts, random excitation, the
#: optimiser under a spectrum) and the random-excitation march they share (the last); nothing else of
#: the harness reads the core, and they read nothing of it but the batch engine.
BATCH_STUDIES = ("piezo_fmu_harness.studies.basins", "piezo_fmu_harness.studies.fractions",
                 "piezo_fmu_harness.studies.bifurcation", "piezo_fmu_harness.studies.random",
                 "piezo_fmu_harness.studies.optimize", "piezo_fmu_harness.random_response")
BATCH_ENGINE = "piezo_fmu.solver.batch"


def test_the_harness_never_imports_the_core_but_the_batch_studies_the_batch_engine():
    for path in sources(HARNESS):
        name = module_name(path)
        core = sorted(m for m in imports(path) if m.split(".")[0] == "piezo_fmu")
        if name.startswith(BATCH_STUDIES):
            core = [m for m in core if not (m == BATCH_ENGINE or m.startswith(BATCH_ENGINE + "."))]
        assert not core, f"{path} imports {core}"


def test_the_batch_studies_say_that_they_read_the_batch_engine():
    for study in BATCH_STUDIES[:-1]:
        folder = HARNESS / "studies" / study.rpartition(".")[2]
        path = folder / "study.py" if (folder / "study.py").exists() else folder / "__init__.py"  # its docstring
        text = " ".join(path.read_text().split())
        assert "reads the simulation core's batch engine" in text, path


@pytest.mark.parametrize("folder", [PACKAGE, HARNESS], ids=["piezo_fmu", "piezo_fmu_harness"])
def test_no_import_cycles_between_modules(folder):
    modules = {module_name(p): p for p in sources(folder)}
    graph = {}
    for name, path in modules.items():
        targets = set()
        for imported in imports(path):
            # "pkg.mod.name" may name an attribute of pkg.mod: keep the longest module it names.
            while imported and imported not in modules:
                imported = imported.rpartition(".")[0]
            if imported and imported != name and not name.startswith(imported + "."):
                targets.add(imported)
        # A package's __init__ importing its submodules is not a cycle with them.
        graph[name] = {t for t in targets if not (path.name == "__init__.py" and t.startswith(name + "."))}
    state: dict[str, int] = {}

    def visit(node, stack):
        state[node] = 1
        for nxt in graph[node]:
            if state.get(nxt) == 1:
                cycle = stack[stack.index(nxt):] + [nxt]
                pytest.fail(f"import cycle: {' -> '.join(cycle)}")
            if nxt not in state:
                visit(nxt, stack + [nxt])
        state[node] = 2

    for node in graph:
        if node not in state:
            visit(node, [node])


@pytest.mark.parametrize("path", sources(PACKAGE) + sources(HARNESS), ids=lambda p: str(p.relative_to(ROOT / "src")))
def test_no_module_over_400_lines_and_no_class_over_250(path):
    text = path.read_text()
    assert text.count("\n") <= MAX_MODULE_LINES, f"{path}: {text.count(chr(10))} lines"
    for node in ast.walk(ast.parse(text)):
        if isinstance(node, ast.ClassDef):
            length = node.end_lineno - node.lineno + 1
            assert length <= MAX_CLASS_LINES, f"{path}: class {node.name} has {length} lines"


def test_no_file_of_the_project_points_at_the_team_folder():
    listed = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout
    offenders = []
    for name in filter(None, listed.decode().split("\0")):
        path = ROOT / name
        if name.startswith(".ci/") or not path.is_file():
            continue
        if b"../" + b"shared" in path.read_bytes():
            offenders.append(name)
    assert not offenders, f"these files point at ../{'shared'}, which a user's clone does not have: {offenders}"


# -- the harness by study ---------------------------------------------------------------------------

STUDIES = "piezo_fmu_harness.studies"


def study_of(module: str):
    """The study a harness module belongs to (``piezo_fmu_harness.studies.<study>``), or None for the
    infrastructure (and for the registry, ``piezo_fmu_harness.studies`` itself)."""
    parts = module.split(".")
    return ".".join(parts[:3]) if len(parts) >= 3 and ".".join(parts[:2]) == STUDIES else None


def harness_modules() -> dict:
    return {module_name(p): p for p in sources(HARNESS)}


def test_the_harness_has_studies_and_infrastructure():
    modules = harness_modules()
    studies = {study_of(m) for m in modules} - {None}
    assert len(studies) >= 7, studies
    assert {"piezo_fmu_harness.fmu", "piezo_fmu_harness.engine", "piezo_fmu_harness.store", "piezo_fmu_harness.spec",
            "piezo_fmu_harness.checks", "piezo_fmu_harness.drawing", "piezo_fmu_harness.cli"} <= set(modules)


@pytest.mark.parametrize("path", sources(HARNESS), ids=lambda p: str(p.relative_to(HARNESS)))
def test_the_studies_never_import_each_other_and_the_infrastructure_never_imports_a_study(path):
    modules = harness_modules()
    name = module_name(path)
    own = study_of(name)
    imported = {m for m in imports(path) if m.startswith(STUDIES + ".") and study_of(m)}
    if name in (STUDIES, "piezo_fmu_harness.cli"):
        return  # the registry collects the studies (the CLI reads the registry only)
    others = sorted(m for m in imported if study_of(m) != own and study_of(m) in {study_of(k) for k in modules})
    assert not others, f"{name} imports {others}"


def test_the_cli_only_collects_the_studies_subcommands():
    found = imports(HARNESS / "cli.py")
    registry = f"{STUDIES}.REGISTRY"
    assert registry in found
    assert not any(study_of(m) for m in found - {registry}), found


def test_a_study_is_one_line_in_the_registry():
    from piezo_fmu_harness import studies

    registered = {f.__module__.rsplit(".", 1)[0] if f.__module__.count(".") > 2 else f.__module__ for f in studies.REGISTRY}
    packages = {study_of(m) for m in harness_modules()} - {None}
    assert registered == packages, (registered, packages)


# -- the FMU's runtime apart from its build -----------------------------------------------------------

FMUS = [ROOT / "fmus" / "PiezoImpactDamper.fmu", ROOT / "fmus" / "PiezoImpactDamper3.fmu"]
SLAVE_SCRIPTS = {"fmi2.py": FMUS[0], "fmi3.py": FMUS[1]}


def test_every_module_of_piezo_fmu_fmi_ships_inside_an_fmu():
    import zipfile

    shipped = set()
    for fmu in FMUS:
        with zipfile.ZipFile(fmu) as archive:
            shipped |= {name for name in archive.namelist() if name.startswith("resources/")}
    for path in sources(PACKAGE / "fmi"):
        relative = path.relative_to(PACKAGE).as_posix()
        if path.name in SLAVE_SCRIPTS:
            with zipfile.ZipFile(SLAVE_SCRIPTS[path.name]) as archive:
                scripts = [n for n in archive.namelist() if n.startswith("resources/") and n.endswith(".py")
                           and "/" not in n[len("resources/"):]]
                assert any(archive.read(n) == path.read_bytes() for n in scripts), f"{relative} is not a slave script"
        else:
            assert f"resources/piezo_fmu/{relative}" in shipped, f"{relative} does not ship inside an FMU"


def test_nothing_that_builds_the_fmus_ships_inside_them():
    import zipfile

    for fmu in FMUS:
        with zipfile.ZipFile(fmu) as archive:
            names = archive.namelist()
        assert not any(name.startswith("resources/piezo_fmu/build") for name in names), fmu.name
    builders = {module_name(p) for p in sources(PACKAGE / "build")}
    assert {"piezo_fmu.build.fmus", "piezo_fmu.build.archive", "piezo_fmu.build.description",
            "piezo_fmu.build.loader"} <= builders
    for path in sources(PACKAGE / "fmi"):
        assert not {m for m in imports(path) if m.startswith("piezo_fmu.build")}, path.name
