"""What each committed loader binary was compiled from, so that a machine without a compiler can
reuse it.

``manifest.json`` (beside the loader's sources) records, for each FMI version and platform
(``fmi2-linux``, ``fmi2-windows``, ``fmi3-linux``, ``fmi3-windows``), the SHA-256 of every input
of the loader's compilation (its C sources, the generated forwarders, the FMI headers, the
compiler's arguments) and the SHA-256 of the binary the committed FMUs carry. The build rewrites
it whenever it writes the committed FMUs.

Where a platform's compiler is absent (a machine with only ``python3``: no ``cc``, no
mingw-w64), :func:`committed_binary` gives the build the binary of the committed FMU instead, but
only when the inputs are those the manifest records and the binary is the one it records: then it
is the binary these sources give, and the rebuild is byte-identical to the committed FMU. Anything
else is a :class:`LoaderUnavailable` that names what changed and what to install. ``--check``
reports a manifest that disagrees with the sources or with the FMUs (:func:`problems`).

The compiler itself is not among the inputs (a machine without it cannot name it): that the
committed binaries are what the compilers give is for ``make fmu-check`` to prove, on a machine
that has them, as CI has.

The manifest is the build's, not the FMUs': no FMU bundles it.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Optional

MANIFEST = Path(__file__).resolve().with_name("manifest.json")
ABOUT = ("Written by `python -m piezo_fmu.build` (see piezo_fmu.build.loader.manifest): the SHA-256 of each "
         "input of each loader binary and of the binary the committed FMUs carry.")


class LoaderUnavailable(RuntimeError):
    """The loader can neither be compiled here nor taken from the committed FMU."""


def sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def key(fmi_version: int, platform: str) -> str:
    """The manifest's name for the loader of FMI ``fmi_version`` on ``platform``."""
    return f"fmi{fmi_version}-{platform}"


def read(path: Optional[Path] = None) -> dict:
    """The manifest's entries by :func:`key` (empty when there is no manifest)."""
    path = path or MANIFEST
    if not path.is_file():
        return {}
    return {name: entry for name, entry in json.loads(path.read_text()).items() if name != "about"}


def update(entries: dict, path: Optional[Path] = None) -> bool:
    """Write ``entries`` over the manifest's (sorted, so that the file is reproducible); True if it
    changed."""
    path = path or MANIFEST
    text = json.dumps({"about": ABOUT, **read(path), **entries}, indent=2, sort_keys=True) + "\n"
    if path.is_file() and path.read_text() == text:
        return False
    path.write_text(text)
    return True


def entry(inputs: dict[str, str], binary: bytes) -> dict:
    """The manifest's entry for a binary compiled from ``inputs`` (digests by input name)."""
    return {"inputs": dict(sorted(inputs.items())), "binary": sha256(binary)}


def changed_inputs(recorded: dict, inputs: dict[str, str]) -> list[str]:
    """The inputs whose digests differ from the recorded ones (or that only one side has)."""
    before = recorded.get("inputs", {})
    return sorted(name for name in set(before) | set(inputs) if before.get(name) != inputs.get(name))


def disagreement(name: str, recorded: Optional[dict], inputs: dict[str, str], binary: Optional[bytes]) -> Optional[str]:
    """Why the manifest's entry ``name`` does not describe ``binary`` compiled from ``inputs``
    (None when it does)."""
    if recorded is None:
        return f"{MANIFEST.name} has no entry {name}"
    changed = changed_inputs(recorded, inputs)
    if changed:
        return f"changed since {MANIFEST.name} was written: {', '.join(changed)}"
    if binary is None:
        return "it is not there"
    if sha256(binary) != recorded.get("binary"):
        return f"its SHA-256 is {sha256(binary)}, {MANIFEST.name} records {recorded.get('binary')}"
    return None


def committed_binary(fmi_version: int, platform: str, inputs: dict[str, str], binary: Optional[bytes],
                     source: Path, missing: Exception) -> bytes:
    """``binary``, the loader that the committed FMU ``source`` carries, when the manifest proves it
    is what ``inputs`` give; otherwise a :class:`LoaderUnavailable` that says why, with
    ``missing`` (the absent compiler and how to install it)."""
    name = key(fmi_version, platform)
    why = disagreement(name, read().get(name), inputs, binary)
    if why is not None:
        raise LoaderUnavailable(f"cannot build the FMI {fmi_version} loader for {platform}: {missing}; and the "
                                f"{platform} loader of {source} cannot stand in for it ({why}); with the compiler "
                                "installed, `make fmu` rebuilds the FMUs and the manifest")
    return binary


def problems(fmi_version: int, binaries: dict[str, bytes], inputs: dict[str, dict[str, str]]) -> list[str]:
    """Where the manifest disagrees with the loader ``binaries`` of an FMU of FMI ``fmi_version``
    (by platform) and with the ``inputs`` of each platform's compilation."""
    recorded = read()
    found = []
    for platform in sorted(inputs):
        name = key(fmi_version, platform)
        why = disagreement(name, recorded.get(name), inputs[platform], binaries.get(platform))
        if why is not None:
            found.append(f"{MANIFEST} disagrees with the {platform} loader ({name}): {why}")
    return found
