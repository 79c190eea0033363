"""What the batch studies take: a damper, and the drives of a study, that the batch engine marches
and the FMU then checks; anything else refused before any work, with the parameter, its value, the
range the studies take and why.

Every damper the FMU accepts is one the engine's closed forms march, but for two limits:

- **The contact in modal form** (:class:`.model.ContactFlow`): exact to about 1e-8 of the state,
  or refused. Two modes that coincide (a contact damped critically, or a circuit as fast as a
  mode) break it at one value, and a part in a million away it holds; time scales too far apart
  break it for good: an impact mass of 1e16 kg beside a barrier's tip of 4 g (its slow modes lost
  in the rounding of the fast ones), or a barrier of 1e-30 N/m (its deflection lost from the
  modes by the balancing).
- **The FMU's step** (:data:`FMU_BRACKETS_PER_STEP`): the FMU that checks every study marches its
  hold steps, ``T / N`` of a forcing period, and takes at most that many brackets of its integrator
  in one step. A main mass so slow (``sqrt(K/M)`` of 1e-10 rad/s: a period of two thousand years)
  that a hold step needs more would be refused by the FMU at its first step.

Each value moved from its default is moved back along a logarithmic line towards the default, and
the boundary found there by bisection is the range the studies take in that parameter's terms, the
other values as given.
"""

from __future__ import annotations

import dataclasses
import math

from ...model.parameters import Parameters, parameter_info

#: Brackets of its integrator the FMU takes in one communication step, at most: the FMU's own
#: ``piezo_fmu.fmi.cosim.MAX_BRACKETS_PER_STEP`` (the solver may not import the FMI layer; a test
#: holds the two equal).
FMU_BRACKETS_PER_STEP = 1e7
#: The FMU's state, its switches and its integer choices: no range to look for.
NOT_RANGED = ("p0", "q0", "dp0", "dq0", "barrier_mode", "voltage_model")
#: A defective contact is isolated when the value moved by this part makes it regular.
NUDGE = 1e-6
#: Relative precision of a boundary (its logarithm's bisection stops within it).
PRECISION = 1e-3


def damper(values: dict) -> Parameters:
    """The damper of the FMU parameter values ``values`` (SI, by the FMU's names, which are the
    :class:`~piezo_fmu.model.parameters.Parameters` fields; the initial state is not used: the
    ensemble's starts are)."""
    names = {f.name for f in dataclasses.fields(Parameters)}
    return Parameters(**{k: v for k, v in values.items() if k in names and k not in ("p0", "q0", "dp0", "dq0")},
                      p0=0.0, q0=0.0, dp0=0.0, dq0=0.0)


def contact_refusal(params: Parameters) -> str | None:
    """Why the engine cannot put the contact of ``params`` in modal form (None when it can)."""
    from .model import BatchModel

    try:
        BatchModel.of(params)
    except ValueError as error:
        return str(error)
    return None


def step_refusal(params: Parameters, ratios, samples: int) -> str | None:
    """Why the FMU would refuse a hold step of the forcing frequencies ``ratios`` (``w / sqrt(K/M)``)
    at ``samples`` nodes a period (None when it takes every one)."""
    from .. import Simulator

    try:
        longest = Simulator(params).longest_bracket
    except ValueError as error:  # what the FMU refuses at its start
        return str(error)
    limit = FMU_BRACKETS_PER_STEP * longest
    slowest = min(ratios) * math.sqrt(params.K / params.M)
    step = 2.0 * math.pi / (slowest * samples) if slowest > 0.0 else math.inf
    if step <= limit:
        return None
    return (f"K = {params.K!r} N/m, M = {params.M!r} kg: the FMU that checks the studies takes at most "
            f"{FMU_BRACKETS_PER_STEP:g} brackets of its integrator ({longest:.3g} s each here) in one step, "
            f"{limit:.3g} s, and a hold step of the forcing, T/{samples} at w = {min(ratios):g} sqrt(K/M) = "
            f"{slowest:.3g} rad/s, is {step:.3g} s: the main mass is too slow for the FMU")


def refusal(values: dict, ratios=(), samples: int = 64) -> str | None:
    """The first reason the studies cannot take the damper ``values`` forced at ``ratios`` (None
    when there is none); a value :class:`Parameters` refuses is one."""
    try:
        params = damper(values)
    except ValueError as error:
        return str(error)
    return contact_refusal(params) or (step_refusal(params, ratios, samples) if len(ratios) else None)


def study_error(values: dict, ratios=(), samples: int = 64) -> str | None:
    """Why the batch studies cannot take the damper of the FMU parameter values ``values`` forced at
    the frequencies ``ratios`` (``w / sqrt(K/M)``) with ``samples`` hold steps a period (None when
    they can): one line with the parameters, their values, the range the studies take and why (see
    the module's text)."""
    why = refusal(values, ratios, samples)
    if why is None:
        return None
    params = damper(values)  # ``refusal`` took it
    if contact_refusal(params) and any(contact_refusal(_moved(params, name, factor)) is None
                                       for name in ("C_eq", "R_load") for factor in (1.0 - NUDGE, 1.0 + NUDGE)):
        return (f"{why}; two of the contact's modes coincide (a contact damped critically, or a circuit as fast as a "
                "mode): move C_eq or R_load by a part in a million")
    ranges = [text for text in (_range(values, ratios, samples, name) for name in _moved_names(values)) if text]
    if not ranges:
        return why
    return f"{why}; the batch studies take {', or '.join(ranges)}, the other values as given"


def _moved(params: Parameters, name: str, factor: float) -> Parameters:
    try:
        return params.replace(**{name: getattr(params, name) * factor})
    except ValueError:
        return params


def _moved_names(values: dict) -> list[str]:
    """The parameters of ``values`` that differ from their defaults and have a range to look for."""
    info = parameter_info()
    explicit = values.get("barrier_mode", info["barrier_mode"]["default"]) == 1
    return [name for name, value in values.items()
            if name in info and name not in NOT_RANGED and value != info[name]["default"]
            and 0.0 < abs(value) < math.inf
            and (explicit or name not in ("M_eq", "K_eq"))]


def _range(values: dict, ratios, samples: int, name: str) -> str | None:
    """``"NAME <= BOUND UNIT (allowed range; NAME = VALUE UNIT here)"``: the boundary between the
    value and its default (which the studies take, the other values as given), by bisection of the
    logarithm; None when the default is refused too."""
    info = parameter_info()[name]
    value, default = float(values[name]), float(info["default"])

    def fails(log_value: float) -> bool:
        return refusal({**values, name: math.copysign(math.exp(log_value), value)}, ratios, samples) is not None

    good, bad = math.log(abs(default)), math.log(abs(value))
    if fails(good):
        return None
    while abs(bad - good) > PRECISION:
        middle = 0.5 * (good + bad)
        good, bad = (good, middle) if fails(middle) else (middle, bad)
    above = abs(value) > abs(default)
    bound = _inward(math.copysign(math.exp(good), value), down=above == (value > 0))
    return (f"{name} {'<=' if above == (value > 0) else '>='} {bound:.3g} {info['unit']} (allowed range; "
            f"{name} = {value!r} {info['unit']} here)")


def _inward(x: float, down: bool) -> float:
    """``x`` rounded to 3 significant digits towards the values the studies take (down or up)."""
    scale = 10.0 ** (math.floor(math.log10(abs(x))) - 2)
    return (math.floor if down else math.ceil)(x / scale) * scale
