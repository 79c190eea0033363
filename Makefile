# Two commands set everything up on a fresh machine: `make nominal` and `make test`.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: nominal test fmu fmu-check bench bench-core bench-fmu clean

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q -e '.[test]'
	touch $(STAMP)

nominal: $(STAMP)
	$(BIN)/python harness/nominal.py

test: $(STAMP)
	$(BIN)/python -m pytest

# The FMU is committed; rebuild it after any change in src/piezo_fmu (byte-reproducible).
fmu: $(STAMP)
	$(BIN)/python -m piezo_fmu.fmu_build

fmu-check: $(STAMP)
	$(BIN)/python -m piezo_fmu.fmu_build --check

bench: bench-core bench-fmu

bench-core: $(STAMP)
	$(BIN)/python benchmarks/bench_core.py

bench-fmu: $(STAMP)
	$(BIN)/python benchmarks/bench_fmu.py

clean:
	rm -rf $(VENV) results build
