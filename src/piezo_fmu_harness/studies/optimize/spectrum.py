"""The random objective's march (:mod:`.search`): one design's realizations with and without the
damper, on the batch engine (:func:`piezo_fmu_harness.random_response.march.march_chunk`), and what
the objective keeps of them.

Every design is marched on the same realizations, 0 to N-1 of the same seed (common random
numbers): two designs' measures differ by what the designs do, not by the inputs' scatter. The
runs without the damper have the design's own main mass, spring and damper; when none of them is
searched, every design's are the same bits.

This module reads the simulation core's batch engine (``piezo_fmu.solver.batch``) in the worker.
"""

from __future__ import annotations

import math

import numpy as np

from ...fmu import FmuRunError
from ...random_response.march import DAMPERS, march_chunk
from ...random_response.spec import RandomSpec
from ...random_response.statistics import paired_ratio
from ...wording import counted


def march_design(spec_dict: dict, values: dict) -> dict:
    """The measures of the damper ``values`` (the FMU's parameters, from rest) under the excitation
    and realizations of ``spec_dict`` (a :class:`~piezo_fmu_harness.random_response.spec.RandomSpec`'s):

    - ``ratio``, ``ratio_low``, ``ratio_high``: the paired ratio of the RMS of the main mass's
      displacement relative to the base, with over without the damper, over the realizations, and
      its 95% interval (null with one realization);
    - ``rms_with``, ``rms_without`` (m): those RMS values;
    - ``power`` (W): the mean power harvested in both loads over the window, with the damper;
    - ``impacts_per_second``: the contact onsets a second, with the damper.

    A design the batch engine cannot take, or a realization whose march failed, raises
    :class:`~piezo_fmu_harness.fmu.FmuRunError`: the design is rejected."""
    import piezo_fmu.solver.batch as batch

    spec = RandomSpec.from_dict(spec_dict).with_(values=values)
    why_not = getattr(batch, "damper_error", None)
    message = why_not(values) if why_not is not None else None
    if message:
        raise FmuRunError(f"the batch engine cannot march this design: {message}")
    plain = spec.to_dict()
    rows = [row["levels"][0] for number, chunk in enumerate(spec.chunks())
            for row in march_chunk(None, plain, number, chunk)["realizations"]]
    failed = [r for r, row in enumerate(rows) if any(row[case]["failed"] or row[case]["ms_relative"] is None
                                                     or row[case]["harvested"] is None for case in DAMPERS)]
    if failed:
        raise FmuRunError(f"the batch engine's march failed on {counted(len(failed), 'realization')} (the first: "
                          f"realization {failed[0]})")
    squares = {case: np.array([row[case]["ms_relative"] for row in rows]) for case in DAMPERS}
    ratio, low, high = paired_ratio(squares["with"], squares["without"])
    window = spec.duration
    return {"ratio": ratio, "ratio_low": _finite(low), "ratio_high": _finite(high),
            "rms_with": math.sqrt(float(squares["with"].mean())),
            "rms_without": math.sqrt(float(squares["without"].mean())),
            "power": float(np.mean([row["with"]["harvested"] / window for row in rows])),
            "impacts_per_second": float(np.mean([row["with"]["impacts"] for row in rows])) / window}


def _finite(value: float):
    return value if math.isfinite(value) else None
