"""Two tiny slaves for the loader's tests (``tests/test_loader.py``): FMI 2.0 (pythonfmu) and
FMI 3.0 (pythonfmu3), the same behaviour.

Parameters ``gain`` (refused if negative or non-finite, RuntimeError at 13), ``m`` (checked at
the end of initialization: refused if not positive, RuntimeError at 13) and ``t_max`` (a step
past it, or of a size that is not positive, is refused); the output ``y = gain * time`` and
``instances``, the number of slaves made so far in the interpreter (a counter on the ``sys``
module, so that two FMUs show whether they share one), and ``references``, the slave's
reference count (what pythonfmu's exception handler used to take away).
``exit_initialization_mode`` logs an information message (status OK, category ``logAll``).
Refusals raise ``PiezoFmuRefusal``, defined here as the project defines it: the loader knows it
by its name.
"""

SLAVE_2 = "LoaderTest2"
SLAVE_3 = "LoaderTest3"

COMMON = '''
import math
import sys


class PiezoFmuRefusal(ValueError):
    """A call the FMU refuses (the project's exception, by name)."""


def count_instance():
    sys.piezo_fmu_test_instances = getattr(sys, "piezo_fmu_test_instances", 0) + 1
    return sys.piezo_fmu_test_instances


class Behaviour:
    def setup(self):
        self.gain, self.m, self.t_max, self.time, self.y = 1.0, 1.0, 1e9, 0.0, 0.0
        self.instances = count_instance()

    def set_gain(self, value):
        if value == 13.0:
            raise RuntimeError("a plain failure, not a refusal")
        if not (math.isfinite(value) and value >= 0.0):
            raise PiezoFmuRefusal(f"gain = {value!r} is out of range; allowed range [0, inf)")
        self.gain = value

    def check_start_values(self):
        if self.m == 13.0:
            raise RuntimeError("a plain failure, not a refusal")
        if not self.m > 0.0:
            raise PiezoFmuRefusal(f"invalid start values: m = {self.m!r} kg is out of range; allowed range (0, inf)")
        self.log("start values checked", self.OK, "logAll")

    def step(self, current_time, step_size):
        if not step_size > 0.0:
            raise PiezoFmuRefusal(f"step size = {step_size!r} s is out of range; allowed range (0, inf)")
        end = current_time + step_size
        if end > self.t_max:  # a message with quotes and a percent sign, as some have
            raise PiezoFmuRefusal(f"the step to t = {end!r} s passes t_max = {self.t_max!r} s, "
                                  f"{100 * end / self.t_max:.0f} % of 't_max'")
        self.time = end
        self.y = self.gain * self.time
'''

SLAVE = '''
class {name}(Behaviour, {base}):
    OK = {status}.ok

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.setup(){time}
        for name, setter in (("gain", self.set_gain), ("m", None), ("t_max", None)):
            self.register_variable({real}(name, causality={causality}.parameter, variability={variability}.fixed,
                                          setter=setter))
        self.register_variable({real}("y", causality={causality}.output))
        for name, getter in (("instances", None), ("references", lambda: sys.getrefcount(self))):
            self.register_variable({integer}(name, causality={causality}.output,
                                             variability={variability}.discrete, getter=getter))

    def exit_initialization_mode(self):
        self.check_start_values()

    def do_step(self, current_time, step_size):
        self.step(current_time, step_size)
        return True
'''

SOURCE_2 = COMMON + """
from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real
from pythonfmu.enums import Fmi2Status
""" + SLAVE.format(name=SLAVE_2, base="Fmi2Slave", status="Fmi2Status", time="", real="Real", integer="Integer",
                   causality="Fmi2Causality", variability="Fmi2Variability")

SOURCE_3 = COMMON + """
from pythonfmu3 import Fmi3Causality, Fmi3Slave, Fmi3Status, Fmi3Variability, Float64, Int32
""" + SLAVE.format(name=SLAVE_3, base="Fmi3Slave", status="Fmi3Status", real="Float64", integer="Int32",
                   causality="Fmi3Causality", variability="Fmi3Variability",
                   time='''
        self.register_variable(Float64("time", causality=Fmi3Causality.independent,
                                       variability=Fmi3Variability.continuous))''')
