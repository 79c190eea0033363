"""Helpers shared by the test modules that drive the FMU, run the command line or record
reliability counts.

No side effects at import (unlike the test modules, which register fmpy loggers).
"""

from __future__ import annotations

import json
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: Where the reliability tests leave what they counted (bad values tried, faults injected).
RELIABILITY_DIR = ROOT / "build" / "reliability"


def set_values(fmu, variables: dict, **values) -> None:
    """Set FMU variables by name (``variables``: name -> fmpy ScalarVariable), Integer or Real."""
    for name, value in values.items():
        v = variables[name]
        if v.type == "Integer":
            fmu.setInteger([v.valueReference], [int(value)])
        else:
            fmu.setReal([v.valueReference], [float(value)])


def read_outputs(fmu, variables: dict) -> dict:
    """Every output of the FMU now, by name."""
    reals = [v for v in variables.values() if v.causality == "output" and v.type == "Real"]
    ints = [v for v in variables.values() if v.causality == "output" and v.type == "Integer"]
    values = dict(zip((v.name for v in reals), fmu.getReal([v.valueReference for v in reals])))
    values.update(zip((v.name for v in ints), fmu.getInteger([v.valueReference for v in ints])))
    return values


def write_record(name: str, data) -> None:
    """Write what a reliability module counted to ``build/reliability/<name>.json``."""
    RELIABILITY_DIR.mkdir(parents=True, exist_ok=True)
    (RELIABILITY_DIR / f"{name}.json").write_text(json.dumps(data, indent=1) + "\n")


def run_cli(*argv) -> int:
    """``piezo-fmu ARGV`` in this process; its exit status."""
    from piezo_fmu_harness import cli

    return cli.main([str(a) for a in argv])


#: ``C_eq`` (N s/m) at which the default damper with ``m = 0.3`` kg has two of its contact's modes
#: coinciding (its fast pair turns from complex to real there; found by bisection to the last bit):
#: the batch engine refuses it as defective (eigenvector condition 4.7e8), one part in 1e9 away it
#: takes it (``test_batch.py``).
DEFECTIVE_C_EQ = 242.31259554649523


def assert_refused(capsys, command: str, argv, words, *more) -> None:
    """``piezo-fmu COMMAND ARGV MORE`` exits with status 2 and an error headed by the command
    (after the usage, for an option argparse itself refuses) that names every one of ``words``."""
    assert run_cli(command, *argv, *more) == 2
    message = capsys.readouterr().err
    assert f"piezo-fmu {command}: error:" in message.splitlines()[-1], message
    for word in words:
        assert word in message, (word, message)
