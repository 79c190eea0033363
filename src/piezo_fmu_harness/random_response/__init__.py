"""The damper's response to random base excitation, marched on the batch engine: what the
random-excitation study (``piezo-fmu random``) and the optimiser's objective under a spectrum share.

- :mod:`.spec`: what a march asks for (the damper, the excitation, the realizations, the window),
  which every worker rebuilds its excitation from;
- :mod:`.march`: a chunk of realizations marched with and without the damper on the same inputs;
- :mod:`.statistics`: the estimates' 95% intervals over the realizations, and the streamed Welch PSD.

It reads the simulation core's batch engine (``piezo_fmu.solver.batch``), as the studies of many
starts do, besides the excitation (:mod:`piezo_fmu_harness.excitation`).
"""
