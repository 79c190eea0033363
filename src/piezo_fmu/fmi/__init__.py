"""The FMI interfaces of the damper, all built from one variable table.

- :mod:`.variables`: the table (names, types, units, bounds, descriptions, start values);
- :mod:`.cosim`: co-simulation behaviour shared by every FMI version;
- :mod:`.fmi2`: the FMI 2.0 co-simulation slave (pythonfmu);
- :mod:`.build`: the reproducible build of the FMUs;
- :mod:`.loader`: the FMUs' linux binary, in front of pythonfmu's (C, compiled by the build).

Importing this package imports neither pythonfmu nor the core.
"""
