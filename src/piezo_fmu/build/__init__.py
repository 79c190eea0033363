"""What builds the FMUs on the developer's machine, apart from what ships inside them
(:mod:`piezo_fmu.fmi`):

- :mod:`.fmus`: the reproducible build of both FMUs (``python -m piezo_fmu.build``);
- :mod:`.description`: the completion of each modelDescription from the variable table;
- :mod:`.archive`: the deterministic archive and the patches to pythonfmu's binaries;
- :mod:`.loader`: the FMUs' own binary, a loader in front of pythonfmu's (C, compiled here, or
  reused from the committed FMUs where its manifest shows the sources give it);
- :mod:`.standalone`: the standalone FMUs (``make fmu-standalone``), the normal ones with the
  CPython runtimes and numpy of :mod:`.runtimes` inside.

Nothing here is imported by an FMU at run time, except :mod:`.own_numpy`, which a standalone FMU
carries as a top-level module of its own.
"""
