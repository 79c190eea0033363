"""The piezo-impact damper's studies, run through ``fmus/PiezoImpactDamper.fmu`` with fmpy.

The harness never imports the simulation core: it knows the model only through the FMU's
modelDescription and talks to it only through fmpy. ``piezo-fmu`` (:mod:`piezo_fmu_harness.cli`) runs
the nominal case (Fig. 3), sweeps (Figs. 4-9) and the two designs (Fig. 10).
"""
