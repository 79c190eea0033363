"""The FMI interfaces of the damper, all built from one variable table.

- :mod:`.variables`: the table (names, types, units, bounds, descriptions, start values);
- :mod:`.cosim`: co-simulation behaviour shared by every FMI version, on the clock of :mod:`.clock`
  (where a step ends, which starts continue the FMU's time);
- :mod:`.me`, :mod:`.me_run`: Model Exchange (FMI 3.0), on the model's equations;
- :mod:`.fmi2`, :mod:`.fmi3`: the FMI 2.0 and FMI 3.0 slaves (pythonfmu, pythonfmu3);
(the reproducible build of the FMUs and their loader are in :mod:`piezo_fmu.build`, apart from what
runs inside them).

Importing this package imports the modules every slave runs on (and with them the core), never
pythonfmu: a host process imports the bundled package once, from the first FMU it loads, and may
delete that FMU's folder after its run (fmpy's ``simulate_fmu`` does); an FMU loaded later must
find every module it needs already imported.
"""

from . import clock, cosim, me, me_run, variables  # noqa: F401 - imported for the FMUs loaded later
