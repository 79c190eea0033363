"""Build the project's FMUs from :mod:`piezo_fmu.fmi`, reproducibly.

Usage (from the repository root)::

    python -m piezo_fmu.build            # (re)write fmus/PiezoImpactDamper.fmu and fmus/PiezoImpactDamper3.fmu
    python -m piezo_fmu.build --check    # exit 1 if a committed FMU is stale
    python -m piezo_fmu.build --fmi 3 --dest other.fmu   # one FMU, elsewhere

Two FMUs, one model:

- ``fmus/PiezoImpactDamper.fmu``, FMI 2.0 co-simulation, made by pythonfmu 0.7.0 from
  :mod:`piezo_fmu.fmi.fmi2`;
- ``fmus/PiezoImpactDamper3.fmu``, FMI 3.0, made by pythonfmu3 from :mod:`piezo_fmu.fmi.fmi3`.

The builders make the archives; this module then completes and freezes them: the
modelDescription gets the units, bounds, exact starts and structure of the variable table
(:mod:`piezo_fmu.build.description`), an identity derived from the content, and the archive is
written with sorted entries, fixed timestamps and modes, stored uncompressed, without
``__pycache__`` (:mod:`piezo_fmu.build.archive`). A rebuild from the same sources is byte-identical,
which is what ``--check`` relies on.

Each FMU's linux and Windows binaries are the project's loader (:mod:`piezo_fmu.build.loader`,
compiled here, for Windows with mingw-w64: it finds a Python for a native host and returns Error
for a refused call); pythonfmu's binaries are kept beside it as
``<modelIdentifier>.pythonfmu.so`` (mended) and ``<modelIdentifier>.pythonfmu.dll``. Without a
compiler for a platform (a machine with only ``python3``), the build takes that platform's loader
from the committed FMU when the loader's manifest shows it is the binary the sources give
(:mod:`piezo_fmu.build.loader.manifest`); writing the committed FMUs rewrites the manifest, and
``--check`` also fails when the manifest disagrees with the sources or the FMUs.

Each FMU carries the core (the ``piezo_fmu`` package, less the build, the slaves and the loader's
sources) and its slave as a top-level module in ``resources/``. At run time it needs a Python 3
with numpy: the host's, or one the loader finds. Both FMUs carry the same package, Model Exchange
included: a host process imports ``piezo_fmu`` once, from whichever FMU it loads first, and every
FMU then runs on that copy.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Optional

# The builders are imported with this module, before any FMU runs in the process: an FMU puts its own
# copy of its builder's package on sys.path, which must not be the one that builds.
import pythonfmu
import pythonfmu3

from piezo_fmu.build import archive, description, loader
from piezo_fmu.fmi.variables import FMI3_VARIABLES, VARIABLES

PACKAGE_DIR = Path(__file__).resolve().parents[1]
#: Files and folders of the package that no FMU needs at run time (each slave travels as its own
#: module; the loader's sources become the FMUs' linux binary). The batch engine (``solver/batch``)
#: travels although no FMU runs it: a process imports ``piezo_fmu`` once, from the first FMU it
#: loads, and a study of many starts must find the engine in that copy too.
NOT_BUNDLED = frozenset({"fmi/fmi2.py", "fmi/fmi3.py", "build"})


@dataclass(frozen=True)
class Target:
    """One FMU: its file, its slave script and the module name the slave has inside it (unique, so
    that it cannot clash in ``sys.modules`` with another FMU in the same host process), the
    builder, the completion of its modelDescription, its capability flags and its variables."""

    fmi_version: int
    model_identifier: str
    slave: str
    slave_module: str
    builder: Callable
    complete: Callable
    identity: str
    capabilities: dict
    variables: tuple

    @property
    def dest(self) -> Path:
        return Path("fmus") / f"{self.model_identifier}.fmu"

    @property
    def linux_binaries(self) -> str:
        return "binaries/linux64/" if self.fmi_version == 2 else "binaries/x86_64-linux/"


def _pythonfmu(script: Path, project_files: list[Path], outdir: Path, capabilities: dict) -> Path:
    return pythonfmu.FmuBuilder.build_FMU(script, dest=outdir, project_files=project_files, **capabilities)


def _pythonfmu3(script: Path, project_files: list[Path], outdir: Path, capabilities: dict) -> Path:
    return pythonfmu3.FmuBuilder.build_FMU(script, dest=outdir, project_files=project_files, **capabilities)


FMI2 = Target(2, "PiezoImpactDamper", "fmi2.py", "piezo_fmu_slave", _pythonfmu, description.complete_fmi2, "guid",
              {"canHandleVariableCommunicationStepSize": True, "canGetAndSetFMUstate": True,
               "canSerializeFMUstate": True},
              VARIABLES)
FMI3 = Target(3, "PiezoImpactDamper3", "fmi3.py", "piezo_fmu_slave3", _pythonfmu3, description.complete_fmi3,
              "instantiationToken",
              {"canHandleVariableCommunicationStepSize": True, "canGetAndSetFMUState": True,
               "canSerializeFMUState": True},
              FMI3_VARIABLES)
TARGETS = {2: FMI2, 3: FMI3}
#: The FMI 2.0 FMU's file, the one the harness and the hosts use by default.
DEFAULT_DEST = FMI2.dest


# -- staging and the builders ------------------------------------------------------------------------

def stage_sources(workdir: Path, target: Target) -> tuple[Path, list[Path]]:
    """Copy the slave of ``target`` (under its module name) and the core package's Python files
    into ``workdir``. Returns the slave script and the project files to bundle beside it."""
    script = workdir / f"{target.slave_module}.py"
    shutil.copyfile(PACKAGE_DIR / "fmi" / target.slave, script)
    package = workdir / "piezo_fmu"
    for source in sorted(PACKAGE_DIR.rglob("*.py")):
        relative = source.relative_to(PACKAGE_DIR)
        prefixes = {"/".join(relative.parts[:n]) for n in range(1, len(relative.parts) + 1)}
        if "__pycache__" in relative.parts or prefixes & NOT_BUNDLED:
            continue
        destination = package / relative
        destination.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(source, destination)
    return script, [package]


def run_builder(target: Target, script: Path, project_files: list[Path], outdir: Path) -> Path:
    """Build a raw FMU, leaving the build process's imports as they were."""
    saved_path, saved_modules = list(sys.path), set(sys.modules)
    try:
        return target.builder(script, list(project_files), outdir, target.capabilities)
    finally:
        sys.path[:] = saved_path
        for name in {script.stem, target.slave_module} - saved_modules:
            sys.modules.pop(name, None)  # staged copies must not shadow the ones inside an FMU


def freeze(raw_fmu: Path, target: Target) -> bytes:
    """The reproducible FMU bytes made from a raw build."""
    files = archive.read_archive(raw_fmu)
    binary, = [name for name in files if name.startswith(target.linux_binaries) and name.endswith(".so")]
    files[binary] = archive.keep_references_on_exception(archive.drop_exit_unload(files[binary]))
    # the slave's class names the binary: the target's model, or a benchmark's floor
    files = loader.install_loader(files, target.fmi_version, Path(binary).stem, committed=target.dest)
    root = target.complete(files["modelDescription.xml"], target.variables, target.capabilities)
    identity = archive.content_identity(files, description.xml_bytes(root))
    root.set(target.identity, identity)
    files["modelDescription.xml"] = description.xml_bytes(root)
    return archive.deterministic_zip(files)


def build_bytes(target: Target = FMI2, script: Optional[Path] = None, modules: tuple[Path, ...] = ()) -> bytes:
    """Build one FMU in a scratch directory and return its bytes.

    ``script`` defaults to the target's slave. Another slave script (the benchmark's no-work slave)
    gets the same bundle, with the target's slave and ``modules`` beside it as modules it can import.
    """
    with tempfile.TemporaryDirectory(prefix="piezo_fmu_build_") as scratch:
        scratch = Path(scratch)
        stage, out = scratch / "stage", scratch / "out"
        stage.mkdir()
        out.mkdir()
        slave, project_files = stage_sources(stage, target)
        if script is not None:
            project_files.append(slave)
            for module in modules:
                shutil.copyfile(module, stage / Path(module).name)
                project_files.append(stage / Path(module).name)
            slave = stage / Path(script).name
            shutil.copyfile(script, slave)
        return freeze(run_builder(target, slave, project_files, out), target)


def build(target: Target = FMI2, dest: Optional[Path] = None) -> Path:
    """Write the FMU of ``target`` to ``dest`` (only if its bytes change) and return the path."""
    data = build_bytes(target)
    dest = Path(dest) if dest is not None else target.dest
    dest.parent.mkdir(parents=True, exist_ok=True)
    if not dest.is_file() or dest.read_bytes() != data:
        dest.write_bytes(data)
    return dest


def check(target: Target = FMI2, dest: Optional[Path] = None) -> list[str]:
    """Problems that make the committed FMU of ``target`` stale (empty when it is up to date),
    the loader's manifest disagreeing with the sources or with the rebuilt FMU included."""
    dest = Path(dest) if dest is not None else target.dest
    if not dest.is_file():
        return [f"{dest} does not exist"]
    old, new = dest.read_bytes(), build_bytes(target)
    problems = loader.manifest_problems(archive.files_of(new), target.fmi_version)
    if old == new:
        return problems
    try:
        changed = archive.differences(old, new)
    except archive.zipfile.BadZipFile:
        return [f"{dest} is not a zip archive", *problems]
    return [f"{dest} differs from a rebuild in: {', '.join(changed) or 'archive layout'}", *problems]


def record_loaders(targets: list[Target]) -> None:
    """Rewrite the loader's manifest for the loaders in the committed FMUs of ``targets``, just built."""
    entries = {}
    for target in targets:
        entries.update(loader.manifest_entries(archive.files_of(target.dest.read_bytes()), target.fmi_version))
    if loader.manifest.update(entries):
        print(f"wrote {os.path.relpath(loader.manifest.MANIFEST)}")


def main(argv: Optional[list[str]] = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m piezo_fmu.build", description=__doc__.split("\n\n")[0])
    parser.add_argument("--fmi", type=int, choices=sorted(TARGETS), action="append",
                        help="the FMI version of the FMU to build (repeat for both; default: both)")
    parser.add_argument("--dest", type=Path, help="FMU path (only with one --fmi; default fmus/<modelIdentifier>.fmu)")
    parser.add_argument("--check", action="store_true",
                        help="do not write; exit 1 if an FMU at its destination differs from a rebuild")
    args = parser.parse_args(argv)
    targets = [TARGETS[version] for version in (args.fmi or sorted(TARGETS))]
    if args.dest is not None and len(targets) != 1:
        parser.error(f"--dest = {args.dest} needs exactly one --fmi (2 or 3), not {len(targets)}")
    missing = loader.missing_compilers()
    if missing:
        print(f"no compiler here for the {' and '.join(missing)} loaders: reusing the committed FMUs' "
              f"(checked against {loader.manifest.MANIFEST.name})")
    status = 0
    for target in targets:
        try:
            if args.check:
                problems = check(target, args.dest)
                for problem in problems:
                    print(f"stale FMU: {problem}; rebuild it with `make fmu` and commit it", file=sys.stderr)
                if not problems:
                    print(f"{args.dest or target.dest} is up to date")
                status = max(status, 1 if problems else 0)
            else:
                print(f"wrote {build(target, args.dest)}")
        except loader.manifest.LoaderUnavailable as unavailable:
            print(f"error: {unavailable}", file=sys.stderr)
            status = 1
    if not args.check and args.dest is None and status == 0:
        record_loaders(targets)
    return status


if __name__ == "__main__":
    sys.exit(main())
