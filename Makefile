# simbench: every target creates its own virtual environment (.venv) on a fresh machine.
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: setup reproduce ablations quick quick-thresholds lint docs test test-fast bench clean

setup: $(STAMP)

# (the install also compiles simbench's C loops, simbench/_ckernels.c and simbench/_lens.c)
$(STAMP): pyproject.toml scripts/setup_system.sh simbench/_ckernels.c simbench/_lens.c
	bash scripts/setup_system.sh
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[dev]'
	$(PY) -c "import simbench.variant as r; print('simbench: libLLVM found:', [f'{v}: {p}' for v, p in r.find_libllvm()][:3])"
	touch $(STAMP)

# The main job: the paper's Table 1, Table 3, Fig. 9 and figures into results/ (renders are
# cached in .cache/simbench), the rig calibration's report (its observations were made, and
# cached, by the tables' calibrated-rig columns), then the pipeline demo into results/demo.
# On 2 worker processes: the same files as one (`reproduce all` from an empty cache: 41 min 44 s on
# an Intel Xeon, 51 min 30 s on an AMD EPYC with AVX-512; renders take ~2.3x as long on a CPU
# without AVX-512; docs/results.md).
reproduce: setup
	$(VENV)/bin/simbench reproduce all --workers 2
	$(VENV)/bin/simbench calibrate --out results/calibration --overwrite
	$(VENV)/bin/simbench demo --out results/demo
	$(VENV)/bin/simbench crosstalk --out results/crosstalk.md

# The built-in ablation studies into results/ablations (every run redone; 32 min 30 s on 2 cores on 2026-11-27).
ablations: setup
	$(VENV)/bin/simbench ablate builtin --fresh --workers 2

# The CI benchmark: the quick run (with the hard scenes' quick form and the robust decoder's stage study
# on them, not part of `all`) checked
# against the committed thresholds, on 2 worker processes
# (the same files as one; from a cold cache 120 s on 2 cores, warm 9.5 s not 13.9 s in one process).
quick: setup
	$(VENV)/bin/simbench reproduce all hard_scenes robust_stages --quick --workers 2 --out .cache/quick --check results/quick/thresholds.toml

# Re-measure the quick run into results/quick and re-derive its thresholds (for an intended
# change only; say why in the commit).
quick-thresholds: setup
	$(VENV)/bin/simbench reproduce all hard_scenes robust_stages --quick --workers 2 --write-thresholds results/quick/thresholds.toml

# Style: ruff's lint rules and formatting (pyproject.toml [tool.ruff], line length 120).
lint: setup
	$(VENV)/bin/ruff check simbench tests scenes
	$(VENV)/bin/ruff format --check simbench tests scenes

# Test processes (pytest-xdist), each test file kept in one of them (--dist loadfile: a file's
# module fixtures, e.g. its renders, are made once), heaviest first (--no-loadscope-reorder:
# tests/conftest.py FILE_SECONDS).  2 = the cores CI has; TEST_WORKERS=0 runs
# everything in this process.
TEST_WORKERS ?= 2
PYTEST := $(PY) -m pytest -q -n $(TEST_WORKERS) --dist loadfile --no-loadscope-reorder --durations=10

# The whole test suite, slow renders included (after the lint).
# The documentation site (mkdocs.yml, docs/): any warning - a broken link, a docstring the API
# reference cannot read - fails the build.
docs: setup
	$(VENV)/bin/mkdocs build --strict --quiet

test: lint docs
	$(PYTEST)

# Developers' loop: everything but the Mitsuba renders.
test-fast: setup
	$(PYTEST) -m "not slow"

bench: setup
	$(VENV)/bin/simbench bench --repeats 30
	$(VENV)/bin/simbench bench --scene shadow --repeats 30
	$(VENV)/bin/simbench bench --rig results/calibration/rig.toml --mode calibrated --repeats 10

clean:
	rm -rf $(VENV) .pytest_cache .benchmarks .cache site
	rm -rf build simbench/*.so
