# The two commands of the README: `make demo` and `make test` (and `make notebooks`).
# Each creates .venv when missing and installs the project into it.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
DEMO   ?= demo-out

.PHONY: demo test install bench notebooks clean cycles-env

$(STAMP): setup.cfg pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test]'
	$(BIN)/python -m ipykernel install --sys-prefix --name python3 >/dev/null
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(BIN)/python benchmarks/demo.py $(DEMO)

test: $(STAMP)
	$(BIN)/python -m pytest -q -ra tests

bench: $(STAMP)
	$(BIN)/python benchmarks/run.py

notebooks: $(STAMP)
	$(BIN)/python notebooks/store.py

# Blender Cycles as a Python module (bpy, about 0.8 GB, its own numpy), for the Cycles
# scenes of benchmarks/cycles/ only: never a dependency of the package.
CYCLES_PYTHON ?= python3.11
CYCLES_VENV   := .venv-cycles
BPY_VERSION   ?= 4.5.0

$(CYCLES_VENV)/.installed:
	test -x $(CYCLES_VENV)/bin/python || $(CYCLES_PYTHON) -m venv $(CYCLES_VENV)
	$(CYCLES_VENV)/bin/python -m pip install --quiet bpy==$(BPY_VERSION)
	touch $@

cycles-env: $(CYCLES_VENV)/.installed

clean:
	rm -rf $(VENV) $(DEMO) .pytest_cache
