# The two commands of the README: `make demo` and `make test`.
# Each creates .venv when it is missing and installs the package with its test extra.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
# one BLAS thread: the matrices are small and the machine may be shared
export OPENBLAS_NUM_THREADS ?= 1
export OMP_NUM_THREADS ?= 1

.PHONY: demo test test-quick test-parallel warmup lint format system-deps bench clean docs docs-check

$(PY):
	@$(PYTHON) -m venv $(VENV)
	@$(PY) -m pip install --quiet --disable-pip-version-check --upgrade pip

$(STAMP): pyproject.toml | $(PY)
	@echo "installing manip_id and its test extra into $(VENV) (once; a few minutes)"
	@$(PY) -m pip install --quiet --disable-pip-version-check -e '.[test]' > $(VENV)/install.log 2>&1 \
		|| { tail -n 30 $(VENV)/install.log; exit 1; }
	@touch $(STAMP)

# Debian packages some tests use (headless Chromium for the meshcat browser test).
# Installed when missing and when apt-get can run; the test skips with a reason otherwise.
system-deps:
	@if ! command -v chromium >/dev/null 2>&1; then \
		if command -v apt-get >/dev/null 2>&1 && [ "$$(id -u)" = 0 ]; then \
			echo "installing chromium (Debian package) for the browser test"; \
			(apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null) \
				|| echo "could not install chromium: the browser test will skip"; \
		else \
			echo "chromium missing and apt-get unavailable: the browser test will skip"; \
		fi; \
	fi

# the numba kernels compiled once, ahead (later runs load them from numba's cache)
warmup: $(STAMP)
	@$(VENV)/bin/manip-id warmup

# the whole suite (CI runs it); tests/README.md says what it costs
test: $(STAMP) system-deps warmup
	$(PY) -m pytest -q

# the suite without the tests marked slow (browser, end-to-end, Monte Carlo)
test-quick: $(STAMP) warmup
	$(PY) -m pytest -q -m "not slow"

# the whole suite on two processes (pytest-xdist): faster on two free cores, about twice
# the memory (tests/README.md gives both)
test-parallel: $(STAMP) system-deps warmup
	$(PY) -m pytest -q -n 2

# A panda that differs from its URDF as a real one does (a 0.8 kg tool, friction, inertias
# off by ~30 %): trained on one excitation (demo-data/run_0.npz), validated on another
# (run_1.npz). The first lines say how much better the identified model predicts than the
# URDF; then the URDF written and the report.
DEMO_ROBOT := panda --friction viscous,coulomb
demo: $(STAMP)
	@$(VENV)/bin/manip-id warmup --quiet
	@$(VENV)/bin/manip-id simulate $(DEMO_ROBOT) --out demo-data --files 2 --seed 2 \
		--joint-terms fv=0.4,fc=0.6 --perturb 0.3 --tool 0.8 --force --quiet
	@$(VENV)/bin/manip-id identify $(DEMO_ROBOT) --data demo-data/run_0.npz \
		--validate demo-data/run_1.npz --method wls --consistent \
		--export-urdf demo-panda.urdf --report demo-report --force

lint: $(STAMP)
	$(VENV)/bin/ruff check manip_id tests experiments
	$(VENV)/bin/ruff format --check manip_id tests experiments
	$(VENV)/bin/mypy

format: $(STAMP)
	$(VENV)/bin/ruff format manip_id tests experiments
	$(VENV)/bin/ruff check --fix manip_id tests experiments

# The documentation (Sphinx, numpydoc, MyST): API reference and worked examples.
DOCS_STAMP := $(VENV)/.docs-installed

$(DOCS_STAMP): pyproject.toml | $(STAMP)
	$(PY) -m pip install --quiet -e '.[docs]'
	touch $(DOCS_STAMP)

docs: $(DOCS_STAMP)
	$(PY) -m sphinx -b html docs docs/_build/html

# The same build as a check (for CI): warnings are errors, output into a temporary folder.
# SPHINX_PYTHON=... builds with another interpreter that has Sphinx, numpydoc and
# myst-parser and this package importable (no .venv is made or changed then).
SPHINX_CHECK = out=$$(mktemp -d) && trap 'rm -rf "$$out"' EXIT && \
	$(1) -m sphinx -b html -W --keep-going -q -d "$$out/doctrees" docs "$$out/html"
ifdef SPHINX_PYTHON
docs-check:
	@$(call SPHINX_CHECK,$(SPHINX_PYTHON))
else
docs-check: $(DOCS_STAMP)
	@$(call SPHINX_CHECK,$(PY))
endif

# Benchmarks of the README's Performance section (minutes; prints tables).
bench: $(STAMP)
	$(PY) experiments/bench_regressor.py
	$(PY) experiments/bench_online.py
	$(PY) experiments/bench_adaptive.py
	$(PY) experiments/bench_identify.py --json experiments/results/bench_identify.json
	$(PY) experiments/bench_startup.py --json experiments/results/bench_startup.json
	$(PY) experiments/bench_simulated.py --json experiments/results/bench_simulated.json
# against FIGAROH when FIGAROH_PYTHON names the interpreter of an environment with figaroh 1.0.2
	$(PY) experiments/bench_figaroh.py --json experiments/results/bench_figaroh.json
	$(PY) experiments/bench_floor.py --build --json experiments/results/bench_floor.json
	$(PY) experiments/profile_identify.py --json experiments/results/profile_identify.json

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache
