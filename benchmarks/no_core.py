"""The co-simulation of the benchmarks' floor FMUs: values read and written as the piezo FMUs do,
but no core and no steps (see ``null_slave.py`` and ``null_slave3.py``)."""

from piezo_fmu.fmi.cosim import ALL, CoSimulation


class NoCore(CoSimulation):
    """Values are read and written as the piezo FMU's are; no core, no steps."""

    def step(self, current_time: float, step_size: float) -> bool:
        return True

    def _update(self, level: int) -> None:
        self._fresh = ALL
