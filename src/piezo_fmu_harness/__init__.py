"""The piezo-impact damper's studies, run through its FMU with fmpy.

The harness never imports the simulation core: it knows the model only through the FMU's
modelDescription and talks to it only through fmpy. ``piezo-fmu`` (:mod:`piezo_fmu_harness.cli`)
runs the nominal case (Fig. 3), sweeps (Figs. 4-9), the two designs (Fig. 10), the load, the
frequency response and the optimiser. :func:`piezo_fmu_harness.fmus.path` finds the FMUs
installed with the package.
"""
