"""The forced response: the damper shaken at its base, swept up and down in
frequency, with and without the damper, each frequency's response a stable orbit or a motion that
is not periodic (``piezo-fmu frequency-response``).

- :mod:`.chains`: the four chains of dependent points on the engine, and their folder;
- :mod:`.results`: the Dataset, the summary and the files;
- :mod:`.figures`: the figures;
- :mod:`.command`: the command line.

The drive, the steady state and its stability are shared with the continuation and the optimiser:
they are in :mod:`piezo_fmu_harness.periodic`.
"""

from __future__ import annotations


def register(commands) -> None:
    """``piezo-fmu frequency-response``."""
    from ...periodic.band import BAND_DEFAULTS
    from ...options import band_options, model_options, results_options, work_options
    from .command import frequency_response

    frequency = commands.add_parser(
        "frequency-response", help="steady response to base motion, up and down",
        description="Shake the damper's base as y = Y sin(w t) at --count frequencies from --ratio-min to "
                    "--ratio-max times w_n = sqrt(K/M); at each, find the periodic steady state (shooting, verified "
                    "by simulation) starting from the previous frequency's state, sweeping up and down, with and "
                    "without the damper. Writes frequency_response.nc/.csv, unstable_orbits.csv, summary.json, "
                    "amplitude.png, power.png and impacts.png; what was asked goes to frequency_response.json and "
                    "each point to points.jsonl (--resume).")
    band_options(frequency, BAND_DEFAULTS)
    model_options(frequency)
    results_options(frequency, "frequency-response", resumable=True)
    work_options(frequency)
    frequency.set_defaults(run=frequency_response)
