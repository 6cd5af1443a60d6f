# The README's commands. Each target creates .venv on first use and installs what it needs.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin

.PHONY: demo test bench lint docs clean

# The main job: every experiment of the paper on built-in shapes, as report/index.html (+ results.json).
demo: $(VENV)/.fast $(VENV)/.viz
	$(BIN)/hamsa reproduce --quick -o report

test: $(VENV)/.fast $(VENV)/.viz $(VENV)/.test $(VENV)/.docs
	$(BIN)/python -m pytest

bench: $(VENV)/.fast $(VENV)/.bench
	$(BIN)/python benchmarks/eigensolve.py

lint: $(VENV)/.test
	$(BIN)/python -m ruff check src tests benchmarks
	$(BIN)/python -m ruff format --check src tests benchmarks

# The documentation site (mkdocs + mkdocstrings, API pages from the docstrings); warnings are errors.
docs: $(VENV)/.docs
	$(BIN)/mkdocs build --strict --quiet
	@echo "docs: $(CURDIR)/site/index.html"

$(VENV)/.docs: $(VENV)/.core
	$(BIN)/pip install -q -e ".[docs]"
	touch $@

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)

$(VENV)/.core: $(BIN)/python pyproject.toml
	$(BIN)/pip install -q -e .
	touch $@

# CHOLMOD is optional: the script never fails, it says what it could not install.
$(VENV)/.fast: $(VENV)/.core
	sh tools/install-cholmod.sh $(BIN)
	touch $@

$(VENV)/.bench: $(VENV)/.core
	$(BIN)/pip install -q -e ".[bench]"
	touch $@

$(VENV)/.test: $(VENV)/.core
	$(BIN)/pip install -q -e ".[test]"
	touch $@

# Rendering (pyvista) plus the system libraries for off-screen EGL; figures and their tests need it.
$(VENV)/.viz: $(VENV)/.core
	sh tools/install-render-libs.sh
	$(BIN)/pip install -q -e ".[viz]"
	touch $@

clean:
	rm -rf $(VENV) build site src/*.egg-info .pytest_cache
