"""What a random-excitation study asks for: the damper, the base excitation (a spectrum at one or more
levels, or a recorded acceleration), the realizations, the window and its warm-up, as a JSON-safe
spec that every worker rebuilds the same excitation from.

**With and without the damper.** Every realization is marched twice on the same input: with the
damper as ``values`` give it, and without it, the same main mass, spring and damper with a gap no
motion of the record reaches (:data:`NO_DAMPER_GAP`: the impact mass, at rest in free flight, never
touches a barrier; the march checks that it makes no impact). The realizations start from rest,
the base too (``p0 = q0 = p0' = q0' = 0``).

**The warm-up** is discarded: by default the time in which the linear oscillator's transient from
rest falls to :data:`SETTLED` of its stationary variance, ``ln(1 / SETTLED) / (2 zeta w_n)``
(``zeta = C / (2 sqrt(K M))``), and at least :data:`HIGHPASS_SETTLE` time constants of the
input's high-pass.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace

#: The warm-up's goal: the linear oscillator's transient variance at this fraction of the stationary one.
SETTLED = 1e-3
#: The warm-up lasts at least this many time constants ``1 / (2 pi f_low)`` of the input's high-pass.
HIGHPASS_SETTLE = 10.0
#: The gap (m) of the runs without the damper: no displacement of a record reaches it.
NO_DAMPER_GAP = 1000.0
#: Steps a block of the march (the bits do not depend on it).
BLOCK = 4096
#: Realizations a chunk (a task of the sweep engine; fixed, so that ``--resume`` finds the same chunks).
CHUNK = 50
#: The response PSD: realizations it averages at most, and the Welch segment (s) at least.
PSD_REALIZATIONS, PSD_SEGMENT = 200, 20.0
#: Kinds of spectrum.
KINDS = ("white", "kanai-tajimi", "clough-penzien", "table")


@dataclass(frozen=True)
class RandomSpec:
    """One random-excitation study (SI).

    ``source``: the excitation's kind and parameters (:func:`build_source`); ``levels``: its levels
    (one-sided PSD, (m/s^2)^2/Hz: ``G0`` of white noise and of the ground filters, the largest
    value of a table), empty for a record; ``values``: the FMU parameters of the damper;
    ``envelope``: a modulating envelope or None; ``step``, ``f_low``, ``warmup`` and ``duration``
    (s, Hz, s, s): the input's step, its high-pass, the discarded warm-up and the window analysed.
    """

    source: dict
    levels: tuple
    values: dict
    realizations: int
    duration: float
    warmup: float
    step: float
    f_low: float
    envelope: dict | None = None
    seed: int = 0
    device: str = "cpu"
    confirm: int = 1
    save_input: int | None = None
    extra: dict = field(default_factory=dict)

    @property
    def warmup_steps(self) -> int:
        return int(round(self.warmup / self.step))

    @property
    def window_steps(self) -> int:
        return int(round(self.duration / self.step))

    @property
    def steps(self) -> int:
        return self.warmup_steps + self.window_steps

    @property
    def without(self) -> dict:
        """The FMU parameters of the runs without the damper."""
        return {**self.values, "d": NO_DAMPER_GAP}

    def chunks(self) -> list[list[int]]:
        """The realizations of each chunk."""
        return [list(range(k, min(k + CHUNK, self.realizations))) for k in range(0, self.realizations, CHUNK)]

    def excitation(self, level_index: int = 0):
        """The :class:`~piezo_fmu_harness.excitation.Excitation` of level ``level_index``."""
        from ..excitation import Excitation, JenningsHousnerTsai, ShinozukaSato

        envelope = None
        if self.envelope is not None:
            kind = {"jennings-housner-tsai": JenningsHousnerTsai, "shinozuka-sato": ShinozukaSato}[self.envelope["kind"]]
            envelope = kind(**self.envelope["parameters"])
        source = build_source(self.source, self.levels[level_index] if self.levels else None)
        return Excitation(source, step=self.step, f_low=self.f_low, envelope=envelope, seed=self.seed)

    def to_dict(self) -> dict:
        return {**asdict(self), "levels": list(self.levels)}

    @classmethod
    def from_dict(cls, data: dict) -> "RandomSpec":
        return cls(**{**data, "levels": tuple(data["levels"])})

    def with_(self, **changes) -> "RandomSpec":
        return replace(self, **changes)


def build_source(source: dict, level: float | None):
    """The spectrum or record that ``source`` describes (``kind`` and its parameters), at ``level``."""
    from ..excitation import CloughPenzien, KanaiTajimi, Record, TablePSD, WhiteNoise

    kind = source["kind"]
    if kind == "white":
        return WhiteNoise(level, source["fmin"], source["fmax"])
    if kind == "kanai-tajimi":
        return KanaiTajimi(level, source["omega_g"], source["zeta_g"], upper=source["upper"])
    if kind == "clough-penzien":
        return CloughPenzien(level, source["omega_g"], source["zeta_g"], upper=source["upper"],
                             omega_f=source["omega_f"], zeta_f=source["zeta_f"])
    if kind == "table":
        table = TablePSD(source["frequencies"], source["densities"], upper=source["upper"], name=source["name"])
        return table.scaled(level)
    if kind == "record":
        return Record(source["step"], source["acceleration"], source["name"])
    raise ValueError(f"source kind = {kind!r} is not known; allowed: {', '.join(KINDS + ('record',))}")


def default_warmup(values: dict, f_low: float) -> float:
    """The warm-up (s) of the module's text for the damper of ``values`` (the FMU's parameters)."""
    M, K, C = values["M"], values["K"], values["C"]
    w_n = math.sqrt(K / M)
    zeta = C / (2.0 * math.sqrt(K * M))
    settle = math.log(1.0 / SETTLED) / (2.0 * zeta * w_n) if zeta > 0.0 else math.inf
    return max(settle if math.isfinite(settle) else 0.0, HIGHPASS_SETTLE / (2.0 * math.pi * f_low))
