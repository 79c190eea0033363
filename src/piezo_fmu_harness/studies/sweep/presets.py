"""Built-in sweeps: the paper's Figs. 4-9.

Each preset is written in the command line's own grammar (``NAME=START:STOP:COUNT`` and
``NAME=VALUE``, SI units) and goes through the same checks against the FMU.

- ``x1-m``: ``x1`` 0-30 mm by 1 mm and ``m`` 0.02-0.20 kg by 6 g, at ``d = 8 mm``
  (panels (a) of Figs. 4-9).
- ``x1-d``: ``x1`` 0-30 mm and ``d`` 3-10 mm, 31 values each, at ``m = 0.1 kg`` (panels (b)).
- ``figs4-9``: both, into ``OUT/x1-m`` and ``OUT/x1-d``, then the six paper figures side by side.
"""

from __future__ import annotations

PRESETS = {
    "x1-m": {"grid": ["x1=0:0.03:31", "m=0.02:0.2:31"], "set": ["d=0.008"],
             "help": "(x1, m) at d = 8 mm, 31 x 31 points: panels (a) of Figs. 4-9"},
    "x1-d": {"grid": ["x1=0:0.03:31", "d=0.003:0.01:31"], "set": ["m=0.1"],
             "help": "(x1, d) at m = 0.1 kg, 31 x 31 points: panels (b) of Figs. 4-9"},
}

#: Presets that run several sweeps, with the panel letter each fills in the paper's figures.
PRESET_SETS = {
    "figs4-9": {"panels": {"a": "x1-m", "b": "x1-d"},
                "help": "both sweeps of Figs. 4-9 (2 x 31 x 31 points) and the six figures"},
}


def preset_names() -> list[str]:
    return list(PRESETS) + list(PRESET_SETS)


def describe() -> str:
    lines = [f"  {name:8s} {spec['help']}" for name, spec in {**PRESETS, **PRESET_SETS}.items()]
    return "\n".join(lines)
