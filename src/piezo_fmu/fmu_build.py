"""Build ``fmus/PiezoImpactDamper.fmu`` from :mod:`piezo_fmu.fmu_slave`, reproducibly.

Usage (from the repository root)::

    python -m piezo_fmu.fmu_build            # (re)write fmus/PiezoImpactDamper.fmu
    python -m piezo_fmu.fmu_build --check    # exit 1 if the committed FMU is stale

pythonfmu 0.7.0 builds the archive; this module then completes and freezes it:

- The modelDescription gets what pythonfmu does not write: ``UnitDefinitions`` (SI base-unit
  exponents), a ``unit`` on every Real, ``min``/``max`` where the table bounds a variable,
  start values written with full (round-trip) precision, and ``ModelStructure/InitialUnknowns``.
  Its random GUID and its generation time are replaced.
- The GUID is derived from the content: the SHA-256 of every other file of the archive (name and
  bytes) and of the modelDescription written with an empty GUID.
- The linux binary is the project's loader (:mod:`piezo_fmu.fmi.loader`: it finds a Python for
  a native host and returns fmi2Error for a refused call); pythonfmu's binary, mended (see
  ``drop_exit_unload`` and ``keep_references_on_exception``), is kept beside it as
  ``PiezoImpactDamper.pythonfmu.so``.
- The archive is written with sorted entries, a fixed timestamp and fixed permissions, stored
  uncompressed (so the bytes do not depend on the zlib build), without ``__pycache__``. A rebuild
  from the same sources is byte-identical, which is what ``--check`` relies on.

The FMU carries the core (the ``piezo_fmu`` package, less this build script, the slave and the
loader's sources) and the slave as the top-level module ``piezo_fmu_slave`` in ``resources/``.
At run time it needs a Python 3 with numpy: the host's, or one the loader finds.
"""

from __future__ import annotations

import argparse
import hashlib
import io
import re
import shutil
import struct
import sys
import tempfile
import uuid
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path
from typing import Iterable, Iterator, Optional

from pythonfmu import FmuBuilder

from piezo_fmu.fmi.loader import install_loader
from piezo_fmu.fmu_slave import VARIABLES, Variable

PACKAGE_DIR = Path(__file__).resolve().parent
SLAVE_SOURCE = PACKAGE_DIR / "fmu_slave.py"
#: Module name of the slave inside the FMU: unique, so that it cannot clash in ``sys.modules``
#: with another pythonfmu FMU loaded into the same host process.
SLAVE_MODULE = "piezo_fmu_slave"
MODEL_IDENTIFIER = "PiezoImpactDamper"
DEFAULT_DEST = Path("fmus") / f"{MODEL_IDENTIFIER}.fmu"
#: Files and folders of the package that the FMU does not need at run time (the slave travels as
#: SLAVE_MODULE; the loader's sources become the FMU's binary).
NOT_BUNDLED = frozenset({"fmu_build.py", "fmu_slave.py", "fmi/loader"})

#: CoSimulation capability flags (pythonfmu defaults otherwise).
CAPABILITIES = {
    "canHandleVariableCommunicationStepSize": True,
    "canGetAndSetFMUstate": True,
    "canSerializeFMUstate": True,
}

#: SI base-unit exponents of every unit the table uses (FMI 2.0 ``BaseUnit`` attributes).
BASE_UNITS = {
    "m": {"m": 1},
    "m/s": {"m": 1, "s": -1},
    "kg": {"kg": 1},
    "kg/m3": {"kg": 1, "m": -3},
    "N": {"kg": 1, "m": 1, "s": -2},
    "N/m": {"kg": 1, "s": -2},
    "N.s/m": {"kg": 1, "s": -1},
    "Pa": {"kg": 1, "m": -1, "s": -2},
    "J": {"kg": 1, "m": 2, "s": -2},
    "W": {"kg": 1, "m": 2, "s": -3},
    "V": {"kg": 1, "m": 2, "s": -3, "A": -1},
    "Ohm": {"kg": 1, "m": 2, "s": -3, "A": -2},
    "V.m/N": {"m": 2, "s": -1, "A": -1},
    "m/V": {"kg": -1, "m": -1, "s": 3, "A": 1},
    "F/m": {"kg": -1, "m": -3, "s": 4, "A": 2},
    "F": {"kg": -1, "m": -2, "s": 4, "A": 2},
    "rad/s": {"s": -1, "rad": 1},
}

#: Fixed archive metadata (the earliest date a zip can hold; regular file, rw-r--r--).
ZIP_DATE_TIME = (1980, 1, 1, 0, 0, 0)
ZIP_FILE_MODE = 0o100644


# -- staging and the pythonfmu build ---------------------------------------------------------------

def stage_sources(workdir: Path) -> tuple[Path, list[Path]]:
    """Copy the slave (as SLAVE_MODULE) and the core package's Python files into ``workdir``.

    Returns the slave script and the project files to bundle beside it.
    """
    script = workdir / f"{SLAVE_MODULE}.py"
    shutil.copyfile(SLAVE_SOURCE, script)
    package = workdir / "piezo_fmu"
    for source in sorted(PACKAGE_DIR.rglob("*.py")):
        relative = source.relative_to(PACKAGE_DIR)
        prefixes = {"/".join(relative.parts[:n]) for n in range(1, len(relative.parts) + 1)}
        if "__pycache__" in relative.parts or prefixes & NOT_BUNDLED:
            continue
        target = package / relative
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(source, target)
    return script, [package]


def run_pythonfmu(script: Path, project_files: Iterable[Path], outdir: Path) -> Path:
    """Build a raw FMU with pythonfmu, leaving the build process's imports as they were."""
    saved_path, saved_modules = list(sys.path), set(sys.modules)
    try:
        return FmuBuilder.build_FMU(script, dest=outdir, project_files=list(project_files),
                                    **CAPABILITIES)
    finally:
        sys.path[:] = saved_path
        for name in {script.stem, SLAVE_MODULE} - saved_modules:
            sys.modules.pop(name, None)  # staged copies must not shadow the ones inside an FMU


# -- completing the modelDescription ---------------------------------------------------------------

def _number(value: float, kind: str) -> str:
    return str(int(value)) if kind == "Integer" else repr(float(value))


def complete_model_description(xml: bytes, variables: Iterable[Variable]) -> ET.Element:
    """The modelDescription with units, bounds, exact starts and InitialUnknowns (GUID left empty)."""
    root = ET.fromstring(xml)
    by_name = {spec.name: spec for spec in variables}

    root.attrib.pop("generationDateAndTime", None)  # a timestamp would break reproducibility
    root.set("generationTool", f"{root.get('generationTool')} via piezo_fmu.fmu_build")
    root.set("guid", "")
    cosim = root.find("CoSimulation")
    for flag, value in CAPABILITIES.items():
        cosim.set(flag, str(value).lower())

    scalars = root.find("ModelVariables").findall("ScalarVariable")
    names = [scalar.get("name") for scalar in scalars]
    if sorted(names) != sorted(by_name):
        raise ValueError(f"the slave's variables {names} do not match the table {sorted(by_name)}")

    used_units = set()
    for scalar in scalars:
        spec = by_name[scalar.get("name")]
        typed = scalar[0]
        attrib = {}
        if spec.unit is not None:
            attrib["unit"] = spec.unit
            used_units.add(spec.unit)
        if spec.min is not None:
            attrib["min"] = _number(spec.min, spec.type)
        if spec.max is not None:
            attrib["max"] = _number(spec.max, spec.type)
        if spec.start is not None:
            attrib["start"] = _number(spec.start, spec.type)
        typed.attrib.clear()
        typed.attrib.update(attrib)

    unknown = set(used_units) - set(BASE_UNITS)
    if unknown:
        raise ValueError(f"no SI base-unit exponents known for the units {sorted(unknown)}; add them to BASE_UNITS")
    unit_definitions = ET.Element("UnitDefinitions")
    for name in sorted(used_units):
        unit = ET.SubElement(unit_definitions, "Unit", {"name": name})
        ET.SubElement(unit, "BaseUnit", {key: str(value) for key, value in BASE_UNITS[name].items()})
    root.insert(list(root).index(cosim) + 1, unit_definitions)

    structure = root.find("ModelStructure")
    for output in structure.find("Outputs"):
        # Co-simulation outputs are the state at the end of the step just taken; the inputs set
        # at a communication point act on the next step only: no direct feedthrough.
        output.set("dependencies", "")
    for old in structure.findall("InitialUnknowns"):
        structure.remove(old)
    initial_unknowns = ET.SubElement(structure, "InitialUnknowns")
    for index, scalar in enumerate(scalars, start=1):
        if scalar.get("causality") in ("output", "calculatedParameter"):
            ET.SubElement(initial_unknowns, "Unknown", {"index": str(index)})
    return root


def _xml_bytes(root: ET.Element) -> bytes:
    ET.indent(root, space="  ")
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True) + b"\n"


def content_guid(files: dict[str, bytes], root: ET.Element) -> str:
    """GUID from the content: SHA-256 of the other files and of the modelDescription sans GUID."""
    digest = hashlib.sha256()
    for name in sorted(files):
        if name != "modelDescription.xml":
            digest.update(name.encode() + b"\0" + len(files[name]).to_bytes(8, "big") + files[name])
    root.set("guid", "")
    digest.update(b"modelDescription.xml\0" + _xml_bytes(root))
    return "{" + str(uuid.UUID(bytes=digest.digest()[:16])) + "}"


# -- the reproducible archive ---------------------------------------------------------------------

def deterministic_zip(files: dict[str, bytes]) -> bytes:
    """The archive of ``files``: sorted, fixed timestamp and mode, stored uncompressed."""
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", compression=zipfile.ZIP_STORED) as archive:
        for name in sorted(files):
            info = zipfile.ZipInfo(name, date_time=ZIP_DATE_TIME)
            info.compress_type = zipfile.ZIP_STORED
            info.create_system = 3  # Unix, so that external_attr means a file mode everywhere
            info.external_attr = ZIP_FILE_MODE << 16
            archive.writestr(info, files[name])
    return buffer.getvalue()


def _elf_sections(data: bytes) -> dict:
    shoff, = struct.unpack_from("<Q", data, 0x28)
    shentsize, shnum, shstrndx = struct.unpack_from("<HHH", data, 0x3A)
    heads = [struct.unpack_from("<IIQQQQIIQQ", data, shoff + i * shentsize) for i in range(shnum)]
    names = heads[shstrndx][4]
    return {data[names + h[0]:data.index(b"\0", names + h[0])].decode(): h for h in heads}


def _symbols(data: bytes) -> Iterator[tuple[str, int, int]]:
    """Name, address and size of every entry of an x86-64 ELF file's ``.symtab``."""
    secs = _elf_sections(data)
    symtab, strtab = secs[".symtab"], secs[".strtab"]
    for off in range(symtab[4], symtab[4] + symtab[5], 24):
        name, _, _, _, value, size = struct.unpack_from("<IBBHQQ", data, off)
        start = strtab[4] + name
        yield data[start:data.index(b"\0", start)].decode(), value, size


def exit_functions(binary: bytes) -> tuple[list[int], Optional[int], int]:
    """What the dynamic loader calls at exit in an x86-64 ELF shared library.

    Returns the addresses in its ``.fini_array`` as far as ``DT_FINI_ARRAYSZ`` reaches, the
    address of pythonfmu's ``onLibraryUnload`` (None if absent), and the file offset of the
    ``DT_FINI_ARRAYSZ`` entry. Raises ``ValueError`` when there is no such entry.
    """
    secs = _elf_sections(binary)
    unload = None
    for name, value, _ in _symbols(binary):
        if "onLibraryUnload" in name:
            unload = value
    fini, rela, dynamic = secs[".fini_array"], secs[".rela.dyn"], secs[".dynamic"]
    entries = {}
    for off in range(rela[4], rela[4] + rela[5], 24):
        where, info, addend = struct.unpack_from("<QQq", binary, off)
        if info & 0xFFFFFFFF == 8 and fini[3] <= where < fini[3] + fini[5]:  # R_X86_64_RELATIVE
            entries[(where - fini[3]) // 8] = addend
    for off in range(dynamic[4], dynamic[4] + dynamic[5], 16):
        tag, size = struct.unpack_from("<qQ", binary, off)
        if tag == 28:  # DT_FINI_ARRAYSZ
            return [entries.get(i) for i in range(size // 8)], unload, off
    raise ValueError("the binary has no DT_FINI_ARRAYSZ")


def drop_exit_unload(binary: bytes) -> bytes:
    """pythonfmu 0.7.0's linux64 binary with ``onLibraryUnload`` taken out of its ``.fini_array``.

    The binary keeps its interpreter guard in a static ``std::shared_ptr<PyState>`` and resets it
    again from ``onLibraryUnload``, a ``__attribute__((destructor))`` function. At process exit
    ``exit()`` runs the static's destructor first (an atexit handler), then the loader's
    ``_dl_fini`` runs ``onLibraryUnload``, which releases the freed control block a second time: a
    use-after-free that corrupts the heap (valgrind; Dask workers abort with "free(): corrupted
    unsorted chunks"). The static's destructor does all the work, at exit and at ``dlclose``, so
    the entry is dropped: ``DT_FINI_ARRAYSZ`` shrinks by one slot (the entry is the array's last,
    and the array runs last to first). Anything else in the table is an error.
    """
    called, unload, size_at = exit_functions(binary)
    if unload is None or not called or called[-1] != unload:
        raise ValueError(f"unexpected exit functions {called} (onLibraryUnload at {unload}): "
                         "not the pythonfmu 0.7.0 binary this mends")
    data = bytearray(binary)
    tag, size = struct.unpack_from("<qQ", binary, size_at)
    struct.pack_into("<qQ", data, size_at, tag, size - 8)
    return bytes(data)


#: One ``Py_XDECREF(this->member)`` as gcc inlined it (``%r13`` = this; 26 bytes): ``mov
#: d8(%r13),%rdi; test %rdi,%rdi; je; mov (%rdi),%eax; test %eax,%eax; js; sub $1,%eax; mov
#: %eax,(%rdi); je rel32``.
_INLINED_XDECREF = rb"\x49\x8b\x7d.\x48\x85\xff\x74.\x8b\x07\x85\xc0\x78.\x83\xe8\x01\x89\x07\x0f\x84...."


def keep_references_on_exception(binary: bytes) -> bytes:
    """pythonfmu's linux binary with its exception handler no longer releasing the slave.

    ``PySlaveInstance::handle_py_exception``, which turns an exception of the slave into Fatal,
    first calls ``cleanPyObject()``, which flushes the log and then ``Py_XDECREF``s the slave's
    class, the slave and its log queue, but leaves the instance holding them and using them on
    the next call. So every exception takes one reference from each: with a slave that raised
    three times in one instance (pythonfmu 0.7.0, fmpy) the log queue's count reached zero, and
    after ten the process died of a segmentation fault. The instance only seemed usable after
    one exception because the slave's reference cycles kept it alive until the garbage
    collector ran. The three inlined decrements (the same 78 bytes in pythonfmu 0.7.0 and
    pythonfmu3 0.3.4) are jumped over: a two-byte ``jmp`` at their start. The log is still
    flushed, and the references are released once, when the instance is freed. Anything else
    in the function is an error.
    """
    secs = _elf_sections(binary)
    text = secs[".text"]
    handlers = [(value, size) for name, value, size in _symbols(binary)
                if "handle_py_exception" in name and "." not in name and size]
    if len(handlers) != 1:
        raise ValueError(f"{len(handlers)} handle_py_exception functions: not a pythonfmu binary this mends")
    value, size = handlers[0]
    start = value - text[3] + text[4]
    found = [m.start() for m in re.finditer(b"(?:" + _INLINED_XDECREF + b"){3}", binary[start:start + size],
                                            flags=re.DOTALL)]
    if len(found) != 1:
        raise ValueError(f"handle_py_exception has {len(found)} runs of three inlined Py_XDECREF: "
                         "not a pythonfmu binary this mends")
    data = bytearray(binary)
    data[start + found[0]:start + found[0] + 2] = bytes([0xEB, 3 * 26 - 2])  # jmp rel8 past the three
    return bytes(data)


def freeze(raw_fmu: Path, variables: Iterable[Variable] = VARIABLES) -> bytes:
    """The reproducible FMU bytes made from a raw pythonfmu build."""
    with zipfile.ZipFile(raw_fmu) as archive:
        files = {name: archive.read(name) for name in archive.namelist()
                 if not name.endswith("/") and "__pycache__" not in name and not name.endswith(".pyc")}
    for name in files:
        if name.startswith("binaries/linux64/") and name.endswith(".so"):
            files[name] = keep_references_on_exception(drop_exit_unload(files[name]))
    identifier = ET.fromstring(files["modelDescription.xml"]).find("CoSimulation").get("modelIdentifier")
    files = install_loader(files, 2, identifier)
    root = complete_model_description(files["modelDescription.xml"], variables)
    guid = content_guid(files, root)
    root.set("guid", guid)
    files["modelDescription.xml"] = _xml_bytes(root)
    return deterministic_zip(files)


def build_bytes(script: Optional[Path] = None) -> bytes:
    """Build the FMU in a scratch directory and return its bytes.

    ``script`` defaults to the piezo slave. Another slave script (the benchmark's no-work slave)
    gets the same bundle, with the piezo slave beside it as a module it can import its table from.
    """
    with tempfile.TemporaryDirectory(prefix="piezo_fmu_build_") as scratch:
        scratch = Path(scratch)
        stage, out = scratch / "stage", scratch / "out"
        stage.mkdir()
        out.mkdir()
        slave, project_files = stage_sources(stage)
        if script is not None:
            project_files.append(slave)
            slave = stage / Path(script).name
            shutil.copyfile(script, slave)
        return freeze(run_pythonfmu(slave, project_files, out))


def build(dest: Path = DEFAULT_DEST) -> Path:
    """Write the FMU to ``dest`` (only if its bytes change) and return the path."""
    data = build_bytes()
    dest = Path(dest)
    dest.parent.mkdir(parents=True, exist_ok=True)
    if not dest.is_file() or dest.read_bytes() != data:
        dest.write_bytes(data)
    return dest


def differences(old: bytes, new: bytes) -> list[str]:
    """Entries that differ between two FMU archives, for a readable staleness report."""
    def entries(data: bytes) -> dict[str, bytes]:
        with zipfile.ZipFile(io.BytesIO(data)) as archive:
            return {name: archive.read(name) for name in archive.namelist()}
    a, b = entries(old), entries(new)
    return sorted(name for name in set(a) | set(b) if a.get(name) != b.get(name))


def check(dest: Path = DEFAULT_DEST) -> list[str]:
    """Problems that make the committed FMU stale (empty when it is up to date)."""
    dest = Path(dest)
    if not dest.is_file():
        return [f"{dest} does not exist"]
    old, new = dest.read_bytes(), build_bytes()
    if old == new:
        return []
    try:
        changed = differences(old, new)
    except zipfile.BadZipFile:
        return [f"{dest} is not a zip archive"]
    return [f"{dest} differs from a rebuild in: {', '.join(changed) or 'archive layout'}"]


def main(argv: Optional[list[str]] = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m piezo_fmu.fmu_build", description=__doc__.split("\n\n")[0])
    parser.add_argument("--dest", type=Path, default=DEFAULT_DEST, help=f"FMU path (default {DEFAULT_DEST})")
    parser.add_argument("--check", action="store_true",
                        help="do not write; exit 1 if the FMU at --dest differs from a rebuild")
    args = parser.parse_args(argv)
    if args.check:
        problems = check(args.dest)
        for problem in problems:
            print(f"stale FMU: {problem}; rebuild it with `make fmu` and commit it", file=sys.stderr)
        if not problems:
            print(f"{args.dest} is up to date")
        return 1 if problems else 0
    path = build(args.dest)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
