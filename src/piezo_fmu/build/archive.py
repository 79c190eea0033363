"""The FMU archive, reproducibly: sorted entries, fixed timestamps and modes, stored uncompressed,
an identity derived from the content, and pythonfmu's linux binary mended (its exit functions,
its exception handler).

A rebuild from the same sources (and the same compiler, for the binaries made here) gives the
same bytes, which is what the build's staleness check relies on.
"""

from __future__ import annotations

import hashlib
import io
import re
import struct
import uuid
import zipfile
from pathlib import Path
from typing import Iterator, Optional

#: Fixed archive metadata (the earliest date a zip can hold; regular file, rw-r--r--).
ZIP_DATE_TIME = (1980, 1, 1, 0, 0, 0)
ZIP_FILE_MODE = 0o100644


def read_archive(path: Path) -> dict[str, bytes]:
    """The files of a raw FMU archive, without folders and compiled Python."""
    with zipfile.ZipFile(path) as archive:
        return {name: archive.read(name) for name in archive.namelist()
                if not name.endswith("/") and "__pycache__" not in name and not name.endswith(".pyc")}


def content_identity(files: dict[str, bytes], description: bytes) -> str:
    """A GUID (FMI 2.0 ``guid``, FMI 3.0 ``instantiationToken``) from the content: the SHA-256 of
    every other file of the archive (name and bytes) and of the ``description`` written with an empty
    identity."""
    digest = hashlib.sha256()
    for name in sorted(files):
        if name != "modelDescription.xml":
            digest.update(name.encode() + b"\0" + len(files[name]).to_bytes(8, "big") + files[name])
    digest.update(b"modelDescription.xml\0" + description)
    return "{" + str(uuid.UUID(bytes=digest.digest()[:16])) + "}"


def deterministic_zip(files: dict[str, bytes], compression: int = zipfile.ZIP_STORED) -> bytes:
    """The archive of ``files``: sorted, fixed timestamp and mode, stored uncompressed (or, for the
    large standalone FMUs, deflated: zlib gives the same bytes for the same input and level)."""
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", compression=compression) as archive:
        for name in sorted(files):
            info = zipfile.ZipInfo(name, date_time=ZIP_DATE_TIME)
            info.compress_type = compression
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


def files_of(data: bytes) -> dict[str, bytes]:
    """The entries of an FMU archive given as bytes, by name."""
    with zipfile.ZipFile(io.BytesIO(data)) as archive:
        return {name: archive.read(name) for name in archive.namelist()}


def differences(old: bytes, new: bytes) -> list[str]:
    """Entries that differ between two FMU archives, for a readable staleness report."""
    a, b = files_of(old), files_of(new)
    return sorted(name for name in set(a) | set(b) if a.get(name) != b.get(name))
