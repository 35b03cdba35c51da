# sosalgo — every target creates .venv from a bare Python 3.11 when needed.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
OUT    ?= outputs
WORKERS ?=
SCHEDULER ?=
BATCH_OPTS := $(if $(WORKERS),--workers $(WORKERS)) $(if $(SCHEDULER),--scheduler $(SCHEDULER))

.PHONY: help venv dev docs demo test test-all lint table1 bench fig1 fig2 fig3 fig4 fig5 pep sweeps figures fuzz soundness clean

help:
	@echo "make help     - this list"
	@echo "make venv     - create .venv and install sosalgo (editable)"
	@echo "make dev      - create .venv with the dev extras (pytest, hypothesis, ruff, dask)"
	@echo "make demo     - create .venv, install, analyze specs/nesterov.yaml into $(OUT)/"
	@echo "make test     - create/reuse .venv with dev extras, run ruff and pytest (TEST_WORKERS processes)"
	@echo "make test-all - make test plus the deep property checks (marked deep)"
	@echo "make lint     - ruff check sosalgo tests bench"
	@echo "make docs     - the documentation site into docs/_build/html (warnings are errors)"
	@echo "make table1   - $(OUT)/table1.csv: shipped specs at kappa 2, 10, 100 vs closed forms (Theorem 1 and interpolation)"
	@echo "make bench    - benchmarks in bench/ (prints a table)"
	@echo "make bench-autolyap - the AutoLyap comparison, AutoLyap (GPL) in its own $(AUTOLYAP_VENV)/"
	@echo "make bench-pepit - the PEP comparison with PEPit, PEPit in its own $(PEPIT_VENV)/"
	@echo "make conformance - every PEPit example sosalgo expresses, against PEPit (docs/conformance.md)"
	@echo "make fig1     - Figure 1: gradient step designed over kappa, with a proven bound"
	@echo "make fig2     - Figure 2: Nesterov momentum designed over kappa, with a proven bound"
	@echo "make fig3     - Figure 3: certified rate on an (h, beta) grid at kappa = 10"
	@echo "make sweeps   - every shipped spec analyzed over 40 kappas (m: 0 specs: no kappa) into $(OUT)/sweeps/"
	@echo "make fig4     - Figure 4: three-parameter family designed with tight certificates"
	@echo "make fig5     - Figure 5: front of certified rate vs noise sensitivity, three-parameter family, kappa 10 and 100"
	@echo "make pep      - worst cases after 1..10 steps (PEP) of gradient descent and Nesterov into $(OUT)/pep"
	@echo "make figures  - table1, fig1, fig2, fig3 and fig4"
	@echo "make fuzz     - the loader fuzz tests with FUZZ_EXAMPLES (default 20000) cases"
	@echo "make soundness - design bounds and composite rates vs independent judges, SOUNDNESS_CASES (300) and COMPOSITE_CASES (200) specs;"
	@echo "                 sublinear constants, noise bounds, PEP bounds, rate brackets on MOMENTUM_CASES (100) random methods each;"
	@echo "                 PEP from initial states and long horizons, hidden-mode brackets, Pareto and objective designs"
	@echo "make clean    - remove CSV, PNG, PDF and JSON files from $(OUT)/"
	@echo "Options: WORKERS=N, SCHEDULER=tcp://host:8786 (batch targets), OUT=DIR"

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(VENV)/.installed: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install -qq -e .
	touch $@

$(VENV)/.installed-dev: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install -qq -e '.[dev]'
	touch $@ $(VENV)/.installed

venv: $(VENV)/.installed
dev: $(VENV)/.installed-dev

demo: $(VENV)/.installed
	$(BIN)/sosalgo analyze specs/nesterov.yaml --out $(OUT) $(BATCH_OPTS)

TEST_WORKERS ?= 3
test: $(VENV)/.installed-dev
	$(BIN)/ruff check sosalgo tests bench
	$(MAKE) docs
	$(BIN)/python -m pytest -n $(TEST_WORKERS) --dist loadgroup -m "not deep"

test-all: $(VENV)/.installed-dev
	$(BIN)/ruff check sosalgo tests bench
	$(BIN)/python -m pytest -n $(TEST_WORKERS) --dist loadgroup

# -E: a fresh build every time (a page that stopped building is never served from the cache);
# the gallery keeps its own cache of computed rates in docs/_build
docs: $(VENV)/.installed-dev
	$(BIN)/python -m sphinx -E -W --keep-going -b html docs docs/_build/html

lint: $(VENV)/.installed-dev
	$(BIN)/ruff check sosalgo tests bench

table1: $(VENV)/.installed
	$(BIN)/sosalgo table1 --certificate theorem1,interpolation --out $(OUT)

bench: $(VENV)/.installed-dev
	$(BIN)/python -m bench $(BENCH_OPTS)

# AutoLyap (GPL) in its own venv, never in $(VENV): bench/autolyap.py runs it in a subprocess.
AUTOLYAP_VENV ?= .venv-autolyap
AUTOLYAP_PKG ?= autolyap
.PHONY: bench-autolyap
$(AUTOLYAP_VENV)/.installed:
	$(PYTHON) -m venv $(AUTOLYAP_VENV)
	$(AUTOLYAP_VENV)/bin/python -m pip install --quiet '$(AUTOLYAP_PKG)'
	touch $@
bench-autolyap: $(VENV)/.installed-dev $(AUTOLYAP_VENV)/.installed
	SOSALGO_AUTOLYAP_PYTHON=$(abspath $(AUTOLYAP_VENV))/bin/python $(BIN)/python -m bench --only autolyap $(BENCH_OPTS)
	SOSALGO_AUTOLYAP_PYTHON=$(abspath $(AUTOLYAP_VENV))/bin/python $(BIN)/python -m bench --only autolyap_operators $(BENCH_OPTS)

# PEPit in its own venv, never in $(VENV): bench/pepit.py runs it in a subprocess.
PEPIT_VENV ?= .venv-pepit
PEPIT_PKG ?= pepit
.PHONY: bench-pepit
$(PEPIT_VENV)/.installed:
	$(PYTHON) -m venv $(PEPIT_VENV)
	$(PEPIT_VENV)/bin/python -m pip install --quiet '$(PEPIT_PKG)'
	touch $@
bench-pepit: $(VENV)/.installed-dev $(PEPIT_VENV)/.installed
	SOSALGO_PEPIT_PYTHON=$(abspath $(PEPIT_VENV))/bin/python $(BIN)/python -m bench --only pepit $(BENCH_OPTS)

# PEPit's examples against sosalgo's commands (bench/conformance/): results.csv and the docs table.
.PHONY: conformance
conformance: $(VENV)/.installed-dev $(PEPIT_VENV)/.installed
	SOSALGO_PEPIT_PYTHON=$${SOSALGO_PEPIT_PYTHON:-$(abspath $(PEPIT_VENV))/bin/python} $(BIN)/python -m bench.conformance $(CONFORMANCE_OPTS)

clean:
	rm -rf $(OUT)/*.csv $(OUT)/*.png $(OUT)/*.pdf $(OUT)/*.json

KAPPA_SWEEP := {from: 1.5, to: 1000, points: 20, scale: log}

fig1: $(VENV)/.installed
	$(BIN)/sosalgo design specs/gradient.yaml --certificate theorem1 --free h --kappa '$(KAPPA_SWEEP)' --time-limit 30 --out $(OUT) $(BATCH_OPTS)
	@echo "Figure 1: $(OUT)/gradient-design.png"

fig2: $(VENV)/.installed
	$(BIN)/sosalgo design specs/nesterov.yaml --certificate theorem1 --free beta --kappa '$(KAPPA_SWEEP)' --time-limit 30 --out $(OUT) $(BATCH_OPTS)
	@echo "Figure 2: $(OUT)/nesterov-design.png"

fig3: $(VENV)/.installed
	$(BIN)/sosalgo grid specs/nesterov.yaml --certificate theorem1 --kappa 10 --points 60 --free h,beta --out $(OUT) $(BATCH_OPTS)
	@echo "Figure 3: $(OUT)/nesterov-grid-k10.png"

fig4: $(VENV)/.installed
	$(BIN)/sosalgo fig4 --kappa '$(KAPPA_SWEEP)' --out $(OUT)/fig4 $(BATCH_OPTS)
	@echo "Figure 4: $(OUT)/fig4/fig4-tight-design.png"

fig5: $(VENV)/.installed
	$(BIN)/sosalgo pareto specs/three-parameter.yaml --kappa 10 --kappa 100 --points 20 --certificate interpolation --out $(OUT)/fig5 $(BATCH_OPTS)
	@echo "Figure 5: $(OUT)/fig5/three-parameter-pareto-k10.png, $(OUT)/fig5/three-parameter-pareto-k100.png"

pep: $(VENV)/.installed
	$(BIN)/sosalgo pep specs/gradient.yaml --kappa 10 --steps 1..10 --measure dist --out $(OUT)/pep $(BATCH_OPTS)
	$(BIN)/sosalgo pep specs/nesterov.yaml --kappa 10 --steps 1..10 --out $(OUT)/pep $(BATCH_OPTS)
	$(BIN)/sosalgo pep specs/gradient-convex.yaml --steps 1..10 --out $(OUT)/pep $(BATCH_OPTS)

SWEEP := {from: 1.5, to: 1000, points: 40, scale: log}
sweeps: $(VENV)/.installed
	for spec in specs/*.yaml; do \
	  if grep -qE '^m: *0+(\.0*)? *(#|$$)' $$spec; then kappa=; else kappa='$(SWEEP)'; fi; \
	  $(BIN)/sosalgo analyze $$spec $${kappa:+--kappa "$$kappa"} --out $(OUT)/sweeps $(BATCH_OPTS) || exit $$?; \
	done

figures: table1 fig1 fig2 fig3 fig4

FUZZ_EXAMPLES ?= 20000
fuzz: $(VENV)/.installed-dev
	SOSALGO_FUZZ_EXAMPLES=$(FUZZ_EXAMPLES) $(BIN)/python -m pytest tests/test_fuzz.py

SOUNDNESS_CASES ?= 300
COMPOSITE_CASES ?= 200
MOMENTUM_CASES ?= 100
soundness: $(VENV)/.installed-dev
	SOSALGO_SOUNDNESS_CASES=$(SOUNDNESS_CASES) SOSALGO_COMPOSITE_CASES=$(COMPOSITE_CASES) \
	  SOSALGO_MOMENTUM_CASES=$(MOMENTUM_CASES) \
	  $(BIN)/python -m pytest tests/test_soundness.py tests/test_soundness_composite.py \
	  tests/test_momentum_judge.py tests/test_soundness_sublinear.py \
	  tests/test_soundness_noise.py tests/test_soundness_pep.py \
	  tests/test_soundness_brackets.py tests/test_soundness_pareto.py
