"""The FMUs as archives: both built from one table, valid, complete and byte-reproducible.

- ``fmpy validate`` reports no problem for either FMU.
- Each committed FMU is a byte-identical rebuild of the sources (the staleness check CI relies
  on), a rebuild is reproducible, and the FMU's identity (FMI 2.0 ``guid``, FMI 3.0
  ``instantiationToken``) is derived from its content.
- ``--check`` fails on a stale FMU and names the entry that changed.
- Each FMU bundles the core and its own slave, and no build tooling; both bundle the same package
  (one host process imports it once, from the FMU it loads first).
- The FMI 3.0 FMU declares the FMI 2.0 one's variables under the same value references, names,
  units, bounds, start values and descriptions (Real as Float64, Integer as Int32), plus ``time``,
  and the Model Exchange interface: its states, derivatives and indicators, each with a unit and a
  description.
"""

from __future__ import annotations

import io
import math
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import pytest
from fmpy import read_model_description
from fmpy.validation import validate_fmu

from piezo_fmu import parameter_info
from piezo_fmu.build import archive
from piezo_fmu.build import fmus as build
from piezo_fmu.fmi import variables

ROOT = Path(__file__).resolve().parents[1]
TARGETS = [build.FMI2, build.FMI3]
IDS = ["fmi2", "fmi3"]


@pytest.mark.parametrize("target", TARGETS, ids=IDS)
def test_fmpy_validate_finds_no_problems(target):
    assert validate_fmu(str(ROOT / target.dest)) == []


@pytest.mark.parametrize("target", TARGETS, ids=IDS)
def test_committed_fmu_is_a_byte_identical_rebuild_of_the_sources(target):
    assert build.check(target, ROOT / target.dest) == [], f"stale FMU: run `make fmu` and commit {target.dest}"


@pytest.mark.parametrize("target", TARGETS, ids=IDS)
def test_rebuild_is_reproducible_and_the_identity_is_derived_from_the_content(target):
    first, second = build.build_bytes(target), build.build_bytes(target)
    assert first == second
    with zipfile.ZipFile(io.BytesIO(first)) as fmu:
        names = fmu.namelist()
        files = {name: fmu.read(name) for name in names}
        assert names == sorted(names)
        assert all(info.date_time == archive.ZIP_DATE_TIME for info in fmu.infolist())
    assert not any("__pycache__" in name or name.endswith(".pyc") for name in names)
    root = ET.fromstring(files["modelDescription.xml"])
    identity = root.get(target.identity)
    root.set(target.identity, "")
    ET.indent(root, space="  ")
    blank = ET.tostring(root, encoding="UTF-8", xml_declaration=True) + b"\n"
    assert archive.content_identity(files, blank) == identity
    assert "generationDateAndTime" not in root.attrib


def test_check_mode_exits_non_zero_on_a_stale_fmu(tmp_path, capsys):
    stale = tmp_path / "stale.fmu"
    with zipfile.ZipFile(ROOT / build.FMI2.dest) as source, zipfile.ZipFile(stale, "w") as target:
        for info in source.infolist():
            data = source.read(info)
            if info.filename == "resources/piezo_fmu/model/parameters.py":
                data += b"\n# edited\n"
            target.writestr(info, data)
    assert build.main(["--fmi", "2", "--check", "--dest", str(stale)]) == 1
    assert "resources/piezo_fmu/model/parameters.py" in capsys.readouterr().err
    fresh = tmp_path / "fresh.fmu"
    build.main(["--fmi", "2", "--dest", str(fresh)])
    assert build.main(["--fmi", "2", "--check", "--dest", str(fresh)]) == 0


def test_dest_needs_exactly_one_fmi_version(capsys):
    with pytest.raises(SystemExit) as exit_:
        build.main(["--dest", "x.fmu"])
    assert exit_.value.code == 2 and "needs exactly one --fmi" in capsys.readouterr().err


@pytest.mark.parametrize("target", TARGETS, ids=IDS)
def test_fmu_bundles_the_core_and_its_slave_but_no_build_tooling(target):
    with zipfile.ZipFile(ROOT / target.dest) as fmu:
        names = set(fmu.namelist())
        assert fmu.read("resources/slavemodule.txt").decode() == target.slave_module
    for module in ("__init__", "model/parameters", "model/barrier", "solver/simulator", "fmi/variables", "fmi/cosim"):
        assert f"resources/piezo_fmu/{module}.py" in names
    assert f"resources/{target.slave_module}.py" in names
    assert not {f"resources/piezo_fmu/{tool}" for tool in build.NOT_BUNDLED} & names
    assert f"{target.linux_binaries}{target.model_identifier}.so" in names


def test_fmi3_declares_the_fmi2_variables_under_the_same_references_and_attributes():
    two = read_model_description(str(ROOT / build.FMI2.dest))
    three = read_model_description(str(ROOT / build.FMI3.dest))
    kinds = {"Real": "Float64", "Integer": "Int32"}
    by_reference = {v.valueReference: v for v in three.modelVariables}
    for v2 in two.modelVariables:
        v3 = by_reference[v2.valueReference]
        assert (v3.name, v3.type, v3.causality, v3.variability) == (v2.name, kinds[v2.type], v2.causality, v2.variability)
        assert (v3.unit, v3.min, v3.max, v3.start, v3.description) == (v2.unit, v2.min, v2.max, v2.start, v2.description)
    time, = [v for v in three.modelVariables if v.causality == "independent"]
    assert (time.name, time.unit) == ("time", "s")
    assert three.modelName == two.modelName == "PiezoImpactDamper"
    assert three.coSimulation.canGetAndSetFMUstate and three.coSimulation.canSerializeFMUstate


def test_fmi3_declares_model_exchange_with_its_states_and_indicators_each_with_a_unit_and_a_description():
    three = read_model_description(str(ROOT / build.FMI3.dest))
    assert three.modelExchange.modelIdentifier == three.coSimulation.modelIdentifier == build.FMI3.model_identifier
    assert three.coSimulation.canHandleVariableCommunicationStepSize
    assert [d.variable.derivative.name for d in three.derivatives] == list(variables.STATES)
    assert [d.variable.name for d in three.derivatives] == [f"der({name})" for name in variables.STATES]
    assert [z.variable.name for z in three.eventIndicators] == list(variables.INDICATORS)
    assert (three.numberOfContinuousStates, three.numberOfEventIndicators) == (12, 5)
    for v in three.modelVariables:
        assert v.description, v.name
        assert v.type != "Float64" or v.unit, v.name


@pytest.mark.parametrize("target", TARGETS, ids=IDS)
def test_the_fmu_carries_the_package_version(target):
    from importlib.metadata import version

    import piezo_fmu

    md = read_model_description(str(ROOT / target.dest))
    assert md.version == piezo_fmu.__version__ == version("piezo-fmu")


def test_both_fmus_bundle_the_same_package_which_a_host_process_imports_once():
    with zipfile.ZipFile(ROOT / build.FMI2.dest) as two, zipfile.ZipFile(ROOT / build.FMI3.dest) as three:
        package = {name for name in two.namelist() if name.startswith("resources/piezo_fmu/")}
        assert package == {name for name in three.namelist() if name.startswith("resources/piezo_fmu/")}
        assert "resources/piezo_fmu/fmi/me.py" in package
        assert all(two.read(name) == three.read(name) for name in package)


@pytest.mark.parametrize("target", TARGETS, ids=IDS)
def test_the_declared_bounds_allow_exactly_the_values_the_fmu_accepts(target):
    """FMI has no exclusive bounds: an open end is declared as the nearest double inside it (``m``
    in (0, inf) kg declares min="5e-324"), so a host that trusts min/max foresees every refusal of
    a single value: the declared end is accepted and the next double outside it is refused."""
    bounds = {name: info["bound"] for name, info in parameter_info().items()}
    md = read_model_description(str(ROOT / target.dest))
    checked = 0
    for variable in md.modelVariables:
        if variable.causality != "parameter" or variable.name not in bounds:
            continue
        bound = bounds[variable.name]
        for declared, outward, limit in ((variable.min, -math.inf, bound.lo), (variable.max, math.inf, bound.hi)):
            if declared is None:
                assert not math.isfinite(limit), f"{variable.name}: the bound end {limit} is not declared"
                continue
            declared = float(declared)
            assert bound.contains(declared), f"{variable.name}: declared {declared} is refused ({bound.describe()})"
            assert not bound.contains(math.nextafter(declared, outward)), f"{variable.name}: {declared} is not the end"
            checked += 1
    assert md.modelVariables[[v.name for v in md.modelVariables].index("m")].min in ("5e-324", 5e-324)
    assert checked >= 25
