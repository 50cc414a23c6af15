# Fresh-machine entry points: `make demo` (set up + main job) and `make test` (set up + tests).
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
TEST_STAMP := $(VENV)/.installed-test

.PHONY: setup setup-test precompile demo lint test test-fast bench reproduce reference-results figures docs docs-text clean

# The main job installs what it needs; `make test` adds the test extras (pytest, rl_zoo3, Ray) on top.
$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	# The local CPU wheel first: a bare `torch` requirement would pull a multi-GB CUDA build.
	$(BIN)/python -m pip install --quiet torch==2.13.0
	$(BIN)/python -m pip install --quiet -e .
	# Compile the kernels now, once (a few minutes), so that a first step takes about a second, not tens of seconds.
	$(BIN)/continuum-gym precompile
	touch $(STAMP)

$(TEST_STAMP): $(STAMP)
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $(TEST_STAMP)

setup: $(STAMP)

setup-test: $(TEST_STAMP)

# After editing the package's code (not only docstrings or comments) the precompiled set no longer matches and is ignored
# (kernels compile on first use, as numba does); this rebuilds it.
precompile: setup
	$(BIN)/continuum-gym precompile

# The main job: analytic baselines and the shipped residual / pure-RL policies on held-out tasks,
# the comparison table (printed, results/evaluate/results.md, .json) and figures; plus the robots' picture.
demo: setup
	$(BIN)/continuum-gym evaluate --out results/evaluate --json results/evaluate/results.json
	$(BIN)/continuum-gym demo --out results/demo

reproduce: setup
	$(BIN)/continuum-gym reproduce --out results/reproduce --json results/reproduce/reproduce.json

# The docs' reference-results page (docs/reference-results.md, its JSON and docs/img/reference/) from the
# committed reference-runs/: continuum-gym evaluate --policies reference-runs on the test split, then the page.
reference-results: setup
	$(BIN)/python scripts/reference_results.py

# The pictures of the README and the environment pages (docs/img/), drawn by `continuum-gym render`.
figures: setup
	$(BIN)/python scripts/render_docs_images.py

# Lint and types first (seconds; [tool.ruff] and [tool.mypy] in pyproject.toml), then the suite.
lint: setup-test
	$(BIN)/ruff check .
	$(BIN)/mypy

test: lint
	$(BIN)/python -m pytest -q -n 2

test-fast: setup-test
	$(BIN)/python -m pytest -q -n 2 -m "not slow"

bench: setup-test
	$(BIN)/python benchmarks/kinematics.py --json results/bench/kinematics.json
	$(BIN)/python benchmarks/envs.py --json results/bench/envs.json
	$(BIN)/python benchmarks/memory.py --json results/bench/memory.json

# The generated text of the docs' pages (env docstrings, the variant tutorial's module) between their markers,
# so that they read in the repository as on the site; tests/test_docs_generated.py fails when it is stale.
docs-text: setup
	$(BIN)/python docs/hooks.py

# The docs site (MkDocs Material): HTML in build/docs, every warning an error (also run by the tests).
docs: setup
	$(BIN)/python -m pip install --quiet -e '.[docs]'
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict

clean:
	rm -rf $(VENV) results build continuum_gym/_precompiled
