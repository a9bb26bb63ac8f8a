# Two entry points that work on a fresh machine: `make run` and `make test`.
# Both create ./.venv, install the package with its test extras, and (when root and missing)
# the system graphviz package used to render diagram pictures and chromium for the report test.
PYTHON ?= python3
VENV   ?= .venv
BIN     = $(VENV)/bin
STAMP   = $(VENV)/.installed

.PHONY: setup system-deps run test diagrams docs docs-check docs-check-full docs-regenerate mutation clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --upgrade pip >/dev/null
	$(BIN)/pip install -e '.[test]'
	touch $(STAMP)

# graphviz is optional (.dot is always written; .svg needs `dot`); chromium (headless) only
# runs the browser test of calibrate's report.html.
system-deps:
	@command -v dot >/dev/null 2>&1 || { \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
	    (apt-get install -y graphviz >/dev/null 2>&1 || \
	     (apt-get update >/dev/null 2>&1 && apt-get install -y graphviz >/dev/null 2>&1)) || \
	    echo "note: could not install graphviz; diagrams are written as .dot only"; \
	  else echo "note: graphviz not installed; diagrams are written as .dot only"; fi; }
	@command -v chromium >/dev/null 2>&1 || { \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
	    (apt-get install -y chromium >/dev/null 2>&1 || \
	     (apt-get update >/dev/null 2>&1 && apt-get install -y chromium >/dev/null 2>&1)) || \
	    echo "note: could not install chromium; the browser test of report.html is skipped"; \
	  else echo "note: chromium not installed; the browser test of report.html is skipped"; fi; }

setup: system-deps $(STAMP)

# The main job: the closed-loop simulation of the built-in default scenario (writes out/simulate,
# its diagram picture included; tracked files are never modified).
run: setup
	$(BIN)/handeye-drake simulate --out out/simulate

# Regenerates the committed diagram pictures in diagrams/ (a deliberate change, to commit).
diagrams: setup
	$(BIN)/python diagrams/closed_loop.py
	$(BIN)/python diagrams/calibrator_alone.py
	$(BIN)/python diagrams/rendered_loop.py

# One worker per core, a test file per worker (module-scoped fixtures are built once per file).
test: setup
	$(BIN)/python -m pytest -n auto --dist loadfile

# The documentation (tools/docs_check.py, docs/writing-docs.md). `docs` builds the site from
# docs/ into out/site (--strict: a broken link or anchor fails). `docs-check` runs every
# documented command with its printed output that is cheap (also run by `make test`, through
# tests/test_docs.py) and compares; `docs-check-full` runs the long ones too (benchmarks,
# reproduce all: minutes; not in CI). `docs-regenerate` rewrites the sections generated from
# committed benchmark results (benchmarks/results/*.json).
docs: setup
	NO_MKDOCS_2_WARNING=1 $(BIN)/python -m mkdocs build --strict

docs-check: setup
	$(BIN)/python tools/docs_check.py

docs-check-full: setup
	$(BIN)/python tools/docs_check.py --full

docs-regenerate: setup
	$(BIN)/python tools/docs_check.py --regenerate

# Mutation testing of estimation/ and calibration/ (docs/testing.md): a seeded sample of
# MUTATION_PER_MODULE one-line mutants per module, each against its module's tests, stopped
# after MUTATION_BUDGET_MIN minutes; reads out/mutation/report.txt. Not part of `make test`/CI.
MUTATION_PER_MODULE ?= 6
MUTATION_BUDGET_MIN ?= 30
MUTATION_SEED ?= 0
MUTATION_STAMP = $(VENV)/.mutation-installed

$(MUTATION_STAMP): $(STAMP)
	$(BIN)/pip install -e '.[test,mutation]'
	touch $(MUTATION_STAMP)

mutation: setup $(MUTATION_STAMP)
	nice $(BIN)/python tools/mutation.py --per-module $(MUTATION_PER_MODULE) \
	  --budget-min $(MUTATION_BUDGET_MIN) --seed $(MUTATION_SEED)

clean:
	rm -rf $(VENV) out .pytest_cache
