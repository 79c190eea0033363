"""Counts and lists as a person writes them, for what the commands print: ``1 point``, ``2 points``,
``3 frequencies``; names joined by commas, or by semicolons when a name holds a comma itself
(``order 1, 2 impacts/cycle; no impacts``)."""

from __future__ import annotations


def plural(noun: str) -> str:
    """The plural of an English noun (or of a phrase's last word): ``branch`` -> ``branches``,
    ``frequency`` -> ``frequencies``, ``connected part`` -> ``connected parts``."""
    if noun.endswith("y") and noun[-2:-1] not in tuple("aeiou"):
        return noun[:-1] + "ies"
    if noun.endswith(("s", "x", "ch", "sh")):
        return noun + "es"
    return noun + "s"


def counted(count: int, noun: str) -> str:
    """``count`` and ``noun``, in the plural unless ``count`` is 1: ``1 point``, ``0 points``."""
    return f"{count:,} {noun if count == 1 else plural(noun)}"


def listed(names) -> str:
    """``names`` joined by ``, ``, or by ``; `` when one of them holds a comma."""
    names = [str(name) for name in names]
    return ("; " if any("," in name for name in names) else ", ").join(names)


def per_cycle(impacts: float) -> str:
    """Impacts per forcing cycle as a rate: ``1 impact/cycle``, ``2.4 impacts/cycle``."""
    return f"{impacts:g} impact{'' if impacts == 1 else 's'}/cycle"
