"""Studies of many starts through the batch engine, checked through the FMU: the machinery the
basin map, the fractions and the bifurcation diagram share.

- :mod:`.chunks`: a study's starts in chunks on the sweep engine, appended to ``points.jsonl``;
- :mod:`.attractors`: the attractors of a study as records, their shares and the basin boundary;
- :mod:`.transients`: how long the starts take to settle, and whether what is left persists;
- :mod:`.destination`: where a start goes, marched through the FMU alone;
- :mod:`.fmu_checks`: the FMU's checks of a study's answers.

The harness reads nothing but the FMU here: it never imports the simulation core.
"""
