"""Generate the loader's forwarding functions from the FMI standard's own headers.

``loader.c`` holds the logic (finding Python, loading pythonfmu's binary, mapping statuses,
relaying the logger); every other function of the FMI API is a forwarder of the same shape,
written here from the standard's declarations so that none is typed by hand::

    python -m piezo_fmu.build.loader.generate 2     # print the FMI 2.0 forwarders
    python -m piezo_fmu.build.loader.generate 3

The exported names come from ``fmi2Functions.h`` / ``fmi3Functions.h`` (their ``FMIx_Export``
declarations), the signatures from ``fmi2FunctionTypes.h`` / ``fmi3FunctionTypes.h``, as fmpy
ships them (``fmpy/c-code``). The output defines:

- ``enum Real``: one index per exported function (``F_fmi2DoStep``, ...), ``F_COUNT``;
- ``REAL_NAMES``: their symbol names, which ``loader.c`` resolves in pythonfmu's binary into
  ``real_functions``;
- a forwarder for every function that takes the instance first and returns a status, except
  those ``loader.c`` writes itself (``HANDWRITTEN``);
- for FMI 3.0, a refusal (``fmi3Error``) for each function that pythonfmu3's binary leaves
  unimplemented by throwing a C++ exception out of its C API (the host process would end in
  ``std::terminate``); they are read from pythonfmu3's own source, shipped in its wheel.

The forwarders are generated at build time, not committed: they are a function of the pinned
headers and of this script, and the build compiles the loader with them (milliseconds).
"""

from __future__ import annotations

import argparse
import re
import sys
from dataclasses import dataclass
from importlib.metadata import distribution
from pathlib import Path

#: Functions with their own code in ``loader.c`` (no instance first, or not a plain forward).
HANDWRITTEN = {
    2: frozenset({"fmi2GetTypesPlatform", "fmi2GetVersion", "fmi2SetDebugLogging", "fmi2Instantiate",
                  "fmi2FreeInstance"}),
    3: frozenset({"fmi3GetVersion", "fmi3SetDebugLogging", "fmi3InstantiateModelExchange",
                  "fmi3InstantiateCoSimulation", "fmi3InstantiateScheduledExecution", "fmi3FreeInstance"}),
}
INSTANCE_TYPE = {2: "fmi2Component", 3: "fmi3Instance"}
STATUS_TYPE = {2: "fmi2Status", 3: "fmi3Status"}
QUALIFIERS = frozenset({"const", "volatile", "struct", "unsigned", "signed"})


def fmi_headers() -> Path:
    """The folder with fmpy's copy of the FMI 2.0 and 3.0 headers."""
    import fmpy

    folder = Path(fmpy.__file__).resolve().parent / "c-code"
    for name in ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi3Functions.h", "fmi3FunctionTypes.h"):
        if not (folder / name).is_file():
            raise FileNotFoundError(f"no {name} in {folder}")
    return folder


@dataclass(frozen=True)
class Parameter:
    declaration: str  # as the definition writes it, with a name
    name: str


@dataclass(frozen=True)
class Function:
    name: str
    returns: str
    parameters: tuple[Parameter, ...]


def _strip_comments(text: str) -> str:
    return re.sub(r"//[^\n]*", "", re.sub(r"/\*.*?\*/", "", text, flags=re.S))


def _parameter(text: str, index: int) -> Parameter:
    """One parameter of a prototype, named ``a<index>`` where the header leaves it unnamed."""
    text = " ".join(text.split())
    array = text.endswith("[]")
    core = text[:-2].rstrip() if array else text
    tokens = re.findall(r"\w+|\*", core)
    words = [t for t in tokens if t != "*" and t not in QUALIFIERS]
    if len(words) >= 2 and tokens[-1] == words[-1]:
        name = words[-1]
        core = core[: core.rstrip().rfind(name)].rstrip()
    else:
        name = f"a{index}"
    return Parameter(f"{core} {name}{'[]' if array else ''}", name)


def function_types(text: str) -> dict[str, Function]:
    """Every ``typedef R fmiXxxTYPE(...)`` of a FunctionTypes header, by function name."""
    found = {}
    pattern = r"typedef\s+([\w\s\*]+?)\s*\b(fmi[23]\w+)TYPE\s*\(([^)]*)\)\s*;"
    for returns, name, params in re.findall(pattern, _strip_comments(text)):
        params = " ".join(params.split())
        parts = [] if params in ("", "void") else [p.strip() for p in params.split(",")]
        found[name] = Function(name, " ".join(returns.split()),
                               tuple(_parameter(p, i) for i, p in enumerate(parts)))
    return found


def exported_names(text: str, version: int) -> list[str]:
    """The functions a Functions header exports, in its order."""
    return re.findall(rf"FMI{version}_Export\s+fmi{version}\w+TYPE\s+(fmi{version}\w+)\s*;", _strip_comments(text))


def pythonfmu3_unimplemented() -> frozenset[str]:
    """FMI 3.0 functions whose pythonfmu3 implementation throws out of the C API.

    pythonfmu3 defines them with its ``NOT_IMPLEMENTED`` macro (a ``throw std::logic_error``
    outside any ``try``), directly or through ``NOT_IMPLEMENTED_GETTER`` / ``_SETTER``. The file
    is found through the installed distribution, not ``import pythonfmu3``: in a process where a
    pythonfmu3 FMU has run, that name can be the FMU's bundled copy, which has no sources.
    """
    source = Path(distribution("pythonfmu3").locate_file(
        "pythonfmu3/pythonfmu-export/src/cppfmu/fmi_functions.cpp")).read_text()
    source = re.sub(r"^#define(?:.*\\\n)*.*$", "", source, flags=re.M)  # the macros' own definitions
    accessors = re.findall(r"NOT_IMPLEMENTED_(GET|SET)TER\((\w+),", source)
    names = {f"fmi3{kind.capitalize()}{suffix}" for kind, suffix in accessors}
    return frozenset(names | set(re.findall(r"(fmi3\w+)\s*\([^{};]*\)\s*\{\s*NOT_IMPLEMENTED\s*;", source)))


def api(version: int, headers: Path | None = None) -> list[Function]:
    """The exported functions of FMI ``version`` with their signatures."""
    headers = headers or fmi_headers()
    types = function_types((headers / f"fmi{version}FunctionTypes.h").read_text())
    names = exported_names((headers / f"fmi{version}Functions.h").read_text(), version)
    missing = [n for n in names if n not in types]
    if not names or missing:
        raise ValueError(f"FMI {version} headers in {headers}: exported {len(names)}, without a TYPE {missing}")
    return [types[n] for n in names]


def _forwarder(function: Function) -> str:
    first, rest = function.parameters[0], function.parameters[1:]
    args = ", ".join(["in->real", *(p.name for p in rest)])
    return (f"{function.returns} {function.name}({', '.join(p.declaration for p in function.parameters)})\n"
            "{\n"
            f"    Instance *in = (Instance *){first.name};\n"
            f"    {function.name}TYPE *f = ({function.name}TYPE *)real_functions[F_{function.name}];\n"
            f"    if (!in || !f) return unsupported(in, \"{function.name}\");\n"
            f"    return finish(in, f({args}));\n"
            "}\n")


def _refusal(function: Function) -> str:
    first = function.parameters[0]
    unused = "".join(f"    (void){p.name};\n" for p in function.parameters[1:])
    return (f"{function.returns} {function.name}({', '.join(p.declaration for p in function.parameters)})\n"
            "{\n"
            f"{unused}"
            f"    return unsupported((Instance *){first.name}, \"{function.name}\");\n"
            "}\n")


def generate(version: int, headers: Path | None = None, unimplemented: frozenset[str] | None = None) -> str:
    """The C source of the forwarders of FMI ``version`` (2 or 3), included by ``loader.c``."""
    if version not in HANDWRITTEN:
        raise ValueError(f"FMI version {version}: only 2 and 3")
    functions = api(version, headers)
    if unimplemented is None:
        unimplemented = pythonfmu3_unimplemented() if version == 3 else frozenset()
    names = {f.name for f in functions}
    if not unimplemented <= names:
        raise ValueError(f"unimplemented functions not in the FMI {version} API: {sorted(unimplemented - names)}")
    forwarded = [f for f in functions if f.name not in HANDWRITTEN[version]]
    odd = [f.name for f in forwarded
           if f.returns != STATUS_TYPE[version] or not f.parameters
           or not f.parameters[0].declaration.startswith(INSTANCE_TYPE[version] + " ")]
    if odd or not HANDWRITTEN[version] <= names:
        raise ValueError(f"FMI {version}: not of the forwarded shape {odd}, "
                         f"hand-written but not in the API {sorted(HANDWRITTEN[version] - names)}")

    lines = [f"/* Generated by piezo_fmu/build/loader/generate.py from fmi{version}Functions.h and "
             f"fmi{version}FunctionTypes.h. */", "",
             "enum Real {"]
    lines += [f"    F_{f.name}," for f in functions]
    lines += ["    F_COUNT", "};", "", "static const char *const REAL_NAMES[F_COUNT] = {"]
    lines += [f"    \"{f.name}\"," for f in functions]
    lines += ["};", "", "/* pythonfmu's functions, resolved by loader.c (NULL where its binary has none) */",
              "static void *real_functions[F_COUNT];", ""]
    for function in forwarded:
        lines.append(_refusal(function) if function.name in unimplemented else _forwarder(function))
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("version", type=int, choices=(2, 3))
    args = parser.parse_args(argv)
    sys.stdout.write(generate(args.version))
    return 0


if __name__ == "__main__":
    sys.exit(main())
