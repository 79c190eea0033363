"""How the kernel's source becomes compiled code.

The kernel is written once, as plain Python functions of scalars, tuples and arrays (the modules
of this package). Each function is registered where it is defined, by one decorator:

- :func:`source` for a function that compiled code calls (a device function on a GPU), with
  ``inline=True`` for the small ones that the CPU compiles into their callers (a call of a compiled
  function costs about as much as their work; a GPU's compiler inlines device functions by itself);
- :func:`entry` for a function that Python calls on the CPU (``parallel=True`` for a loop over the
  trajectories with ``prange``), or, with ``gpu=True``, a GPU launch.

A :class:`Target` compiles a registered function on first use with the compiler its registration
asks for, and binds every registered function that it calls to the target's compiled version of
it: the globals the function names, replaced in a copy of its module's. Nothing is looked up by
name, and run uncompiled the functions are the kernel itself (slowly).
"""

from __future__ import annotations

import threading
import types
from typing import Callable

#: The registered functions, and how each is compiled: "source", "inline", "serial", "parallel"
#: or "gpu" (the keyword of :class:`Target`'s compilers).
_KINDS: dict = {}


def source(function: Callable | None = None, *, inline: bool = False):
    """Register ``function`` as part of the kernel's source, called from compiled code; with
    ``inline``, compiled into its callers on the CPU."""
    def register(f):
        _KINDS[f] = "inline" if inline else "source"
        return f
    return register(function) if function is not None else register


def entry(function: Callable | None = None, *, parallel: bool = False, gpu: bool = False):
    """Register ``function`` as an entry point of the kernel: called from Python on the CPU
    (``parallel``: its ``prange`` loops run on every core), or launched on a GPU (``gpu``)."""
    def register(f):
        _KINDS[f] = "gpu" if gpu else "parallel" if parallel else "serial"
        return f
    return register(function) if function is not None else register


class Target:
    """The kernel compiled for one target: ``compilers`` by the kinds of :func:`source` and
    :func:`entry` (``source``, ``inline``, ``serial``, ``parallel``, ``gpu``; a kind a target has no
    compiler for cannot be compiled there). Calling it with a registered function gives that
    function's compiled version, compiled on first use."""

    def __init__(self, **compilers: Callable):
        self._compilers = compilers
        self._compiled: dict = {}
        self._lock = threading.RLock()

    def __call__(self, function: Callable):
        with self._lock:
            compiled = self._compiled.get(function)
            if compiled is None:
                kind = _KINDS.get(function)
                if kind not in self._compilers:
                    raise ValueError(f"{function.__qualname__} is not compiled for this target "
                                     f"(registered as {kind!r}; compiled here: {sorted(self._compilers)})")
                compiled = self._compiled[function] = self._compilers[kind](self._bound(function))
            return compiled

    def _bound(self, function: Callable) -> Callable:
        """A copy of ``function`` whose calls of registered functions call their compiled versions."""
        namespace = dict(function.__globals__)
        for name in function.__code__.co_names:  # the globals it names
            value = namespace.get(name)
            if isinstance(value, types.FunctionType) and value in _KINDS and value is not function:
                namespace[name] = self(value)
        clone = types.FunctionType(function.__code__, namespace, function.__name__, function.__defaults__,
                                   function.__closure__)
        clone.__module__, clone.__qualname__, clone.__doc__ = function.__module__, function.__qualname__, function.__doc__
        return clone
