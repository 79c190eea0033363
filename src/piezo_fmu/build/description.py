"""Completing the modelDescriptions that pythonfmu and pythonfmu3 write, from the variable table.

Neither builder writes units, ``min``/``max`` or full-precision start values (pythonfmu writes no
``InitialUnknowns`` either), and both stamp the build time and a random identity. The build fixes
all of it from :data:`piezo_fmu.fmi.variables.VARIABLES` (and, for FMI 3.0, the variables of the
other interfaces), so that every FMU says the same of each variable and is byte-reproducible; the
identity is set afterwards from the content (:func:`piezo_fmu.build.archive.content_identity`).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from typing import Iterable

from piezo_fmu import __version__
from piezo_fmu.fmi.variables import Variable

#: The name of the FMUs' model (FMI 3.0's modelIdentifier differs: it names the binary).
MODEL_NAME = "PiezoImpactDamper"

#: SI base-unit exponents of every unit the table uses (FMI 2.0 ``BaseUnit`` attributes).
BASE_UNITS = {
    "m": {"m": 1},
    "m/s": {"m": 1, "s": -1},
    "kg": {"kg": 1},
    "kg/m3": {"kg": 1, "m": -3},
    "N": {"kg": 1, "m": 1, "s": -2},
    "N/m": {"kg": 1, "s": -2},
    "N.s/m": {"kg": 1, "s": -1},
    "Pa": {"kg": 1, "m": -1, "s": -2},
    "J": {"kg": 1, "m": 2, "s": -2},
    "W": {"kg": 1, "m": 2, "s": -3},
    "V": {"kg": 1, "m": 2, "s": -3, "A": -1},
    "Ohm": {"kg": 1, "m": 2, "s": -3, "A": -2},
    "V.m/N": {"m": 2, "s": -1, "A": -1},
    "m/V": {"kg": -1, "m": -1, "s": 3, "A": 1},
    "F/m": {"kg": -1, "m": -3, "s": 4, "A": 2},
    "F": {"kg": -1, "m": -2, "s": 4, "A": 2},
    "rad/s": {"s": -1, "rad": 1},
    "s": {"s": 1},
    "1/s": {"s": -1},
    "m/s2": {"m": 1, "s": -2},
    "V/s": {"kg": 1, "m": 2, "s": -4, "A": -1},
}


def _number(value: float, kind: str) -> str:
    return str(int(value)) if kind == "Integer" else repr(float(value))


def _typed_attributes(spec: Variable, used_units: set) -> dict:
    """``unit``, ``min``, ``max`` and ``start`` of one variable, as the table gives them."""
    attrib = {}
    if spec.unit is not None:
        attrib["unit"] = spec.unit
        used_units.add(spec.unit)
    if spec.min is not None:
        attrib["min"] = _number(spec.min, spec.type)
    if spec.max is not None:
        attrib["max"] = _number(spec.max, spec.type)
    if spec.start is not None:
        attrib["start"] = _number(spec.start, spec.type)
    return attrib


def _unit_definitions(used_units: set) -> ET.Element:
    unknown = set(used_units) - set(BASE_UNITS)
    if unknown:
        raise ValueError(f"no SI base-unit exponents known for the units {sorted(unknown)}; add them to BASE_UNITS")
    unit_definitions = ET.Element("UnitDefinitions")
    for name in sorted(used_units):
        unit = ET.SubElement(unit_definitions, "Unit", {"name": name})
        ET.SubElement(unit, "BaseUnit", {key: str(value) for key, value in BASE_UNITS[name].items()})
    return unit_definitions


#: Capability flags that only the co-simulation interface element has.
CO_SIMULATION_ONLY = frozenset({"canHandleVariableCommunicationStepSize"})


def _common(root: ET.Element, identity: str, capabilities: dict, interfaces: Iterable[str]) -> None:
    """What both versions need: no build time, the build named, the identity left empty, the
    package's version, the capability flags set on each interface element that has them."""
    root.attrib.pop("generationDateAndTime", None)  # a timestamp would break reproducibility
    root.set("generationTool", f"{root.get('generationTool')} via piezo_fmu.build")
    root.set(identity, "")
    root.set("version", __version__)
    for interface in interfaces:
        element = root.find(interface)
        if element is not None:
            for flag, value in capabilities.items():
                if interface == "CoSimulation" or flag not in CO_SIMULATION_ONLY:
                    element.set(flag, str(value).lower())


def _check_names(names: list, by_name: dict) -> None:
    if sorted(names) != sorted(by_name):
        raise ValueError(f"the slave's variables {names} do not match the table {sorted(by_name)}")


def complete_fmi2(xml: bytes, variables: Iterable[Variable], capabilities: dict) -> ET.Element:
    """The FMI 2.0 modelDescription with units, bounds, exact starts, the capability flags and
    InitialUnknowns (GUID left empty)."""
    root = ET.fromstring(xml)
    by_name = {spec.name: spec for spec in variables}
    _common(root, "guid", capabilities, ["CoSimulation"])
    scalars = root.find("ModelVariables").findall("ScalarVariable")
    _check_names([scalar.get("name") for scalar in scalars], by_name)
    used_units = set()
    for scalar in scalars:
        typed = scalar[0]
        typed.attrib.clear()
        typed.attrib.update(_typed_attributes(by_name[scalar.get("name")], used_units))
    root.insert(list(root).index(root.find("CoSimulation")) + 1, _unit_definitions(used_units))

    structure = root.find("ModelStructure")
    for output in structure.find("Outputs"):
        # Co-simulation outputs are the state at the end of the step just taken; the inputs set
        # at a communication point act on the next step only: no direct feedthrough.
        output.set("dependencies", "")
    for old in structure.findall("InitialUnknowns"):
        structure.remove(old)
    initial_unknowns = ET.SubElement(structure, "InitialUnknowns")
    for index, scalar in enumerate(scalars, start=1):
        if scalar.get("causality") in ("output", "calculatedParameter"):
            ET.SubElement(initial_unknowns, "Unknown", {"index": str(index)})
    return root


def complete_fmi3(xml: bytes, variables: Iterable[Variable], capabilities: dict) -> ET.Element:
    """The FMI 3.0 modelDescription with the model's name, units, bounds, exact starts and the
    capability flags (instantiationToken left empty). pythonfmu3 writes the ModelStructure."""
    root = ET.fromstring(xml)
    by_name = {spec.name: spec for spec in variables}
    _common(root, "instantiationToken", capabilities, ["ModelExchange", "CoSimulation"])
    root.set("modelName", MODEL_NAME)
    elements = list(root.find("ModelVariables"))
    _check_names([element.get("name") for element in elements], by_name)
    used_units = set()
    for element in elements:
        attrib = _typed_attributes(by_name[element.get("name")], used_units)
        for key in ("unit", "min", "max", "start"):
            element.attrib.pop(key, None)
        element.attrib.update(attrib)
    for old in root.findall("UnitDefinitions"):
        root.remove(old)
    last_interface = max(list(root).index(e) for e in root if e.tag in ("ModelExchange", "CoSimulation"))
    root.insert(last_interface + 1, _unit_definitions(used_units))
    _initial_unknowns_fmi3(root.find("ModelStructure"), elements)
    return root


def _initial_unknowns_fmi3(structure: ET.Element, elements: list) -> None:
    """The InitialUnknowns FMI 3.0 requires, in value-reference order: the outputs and the
    continuous states and state derivatives whose ``initial`` is not exact, and the calculated
    parameters. pythonfmu3 leaves out the states that are locals."""
    by_reference = {element.get("valueReference"): element for element in elements}
    unknown = set()
    for derivative in structure.findall("ContinuousStateDerivative"):
        element = by_reference[derivative.get("valueReference")]
        unknown.update({element.get("valueReference"), element.get("derivative")})
    for element in elements:
        if element.get("causality") in ("output", "calculatedParameter"):
            unknown.add(element.get("valueReference"))
    unknown = {vr for vr in unknown if by_reference[vr].get("initial") != "exact"}
    for old in structure.findall("InitialUnknown"):
        structure.remove(old)
    position = len(structure) - len(structure.findall("EventIndicator"))
    for vr in sorted(unknown, key=int, reverse=True):
        structure.insert(position, ET.Element("InitialUnknown", {"valueReference": vr}))


def xml_bytes(root: ET.Element) -> bytes:
    """The modelDescription's bytes, indented."""
    ET.indent(root, space="  ")
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True) + b"\n"
