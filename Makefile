# vslbook: two commands.
#   make book   set up .venv and execute every notebook at $(VSLBOOK_BUDGET) (default: reduced)
#   make test   set up .venv and run the tests, notebooks included, at the smoke budget
# Setup is idempotent: the stamp .venv/.installed is rebuilt only when pyproject.toml or
# this Makefile changes.

PYTHON ?= python3.11
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
TORCH  := torch==2.13.0
# MyoSuite declares gymnasium<1.3 and ~70 optional packages; its hand tasks run on the
# pinned stack when installed without dependencies (see vslbook/envs/step_based.py).
MYO    := myosuite==3.0.0 myo-sim==0.2.3 termcolor colorednoise
# The robot tasks of Chapters 3-4 read fancy-gym's MIT model files from its wheel; its Python
# code needs mujoco 2.3.3 / gymnasium < 1 and is never imported (vslbook/envs/robot/assets.py).
FANCY  := fancy-gym==0.3.0
NB_SRC := $(sort $(wildcard notebooks/[0-9][0-9]_*.py))
NB_IPY := $(NB_SRC:.py=.ipynb)
VSLBOOK_BUDGET ?= reduced
export MPLBACKEND ?= Agg
export MUJOCO_GL ?= disable
export PYTHONHASHSEED := 0

.PHONY: setup myo book test test-fast notebooks lab lint clean help
.DEFAULT_GOAL := help

help:
	@echo "make book   execute the whole book at VSLBOOK_BUDGET=$(VSLBOOK_BUDGET) into build/"
	@echo "make test   run the test suite, notebooks included (smoke budget)"
	@echo "make lab    open JupyterLab on notebooks/"
	@echo "make lint   ruff"

$(BIN)/python:
	@command -v $(PYTHON) >/dev/null 2>&1 || { echo "need $(PYTHON) (set PYTHON=...)"; exit 1; }
	$(PYTHON) -m venv $(VENV)

$(STAMP): pyproject.toml Makefile | $(BIN)/python
	$(BIN)/python -m pip install --quiet --upgrade pip
	# CPU torch first: anything asking for torch later finds it satisfied (no CUDA build).
	$(BIN)/python -m pip install --quiet $(TORCH)
	$(BIN)/python -m pip install --quiet -e ".[notebooks,dev]"
	$(BIN)/python -m ipykernel install --sys-prefix --name python3 >/dev/null
	$(BIN)/python -m pip install --quiet --no-deps $(MYO)
	$(BIN)/python -m pip install --quiet --no-deps $(FANCY)
	touch $(STAMP)

setup: $(STAMP)

# MyoSuite's hand tasks alone (already part of setup); --no-deps keeps the pinned stack.
myo: | $(BIN)/python
	$(BIN)/python -m pip install --quiet --no-deps $(MYO)

notebooks/%.ipynb: notebooks/%.py $(STAMP)
	$(BIN)/jupytext --quiet --to ipynb --output $@ $<

notebooks: $(NB_IPY)

book: notebooks
	mkdir -p build/notebooks build/html build/figures
	@for nb in $(NB_IPY); do \
	  echo "== $$nb (budget $(VSLBOOK_BUDGET))"; \
	  start=$$(date +%s); \
	  VSLBOOK_BUDGET=$(VSLBOOK_BUDGET) VSLBOOK_FIGURES=$(CURDIR)/build/figures \
	    $(BIN)/jupyter nbconvert --to notebook --execute --ExecutePreprocessor.timeout=-1 \
	    --output-dir build/notebooks $$nb || exit 1; \
	  $(BIN)/jupyter nbconvert --to html --output-dir build/html \
	    build/notebooks/$$(basename $$nb) >/dev/null 2>&1 || exit 1; \
	  echo "   $$(( $$(date +%s) - start )) s"; \
	done
	@echo "book written to build/ (notebooks/, html/, figures/)"

# pytest exits 5 when nothing is collected; that is not a failure of the suite.
test: notebooks
	VSLBOOK_BUDGET=smoke VSLBOOK_FIGURES=$(CURDIR)/build/figures-smoke \
	  $(BIN)/python -m pytest -q --durations=15 tests --nbmake --nbmake-timeout=2400 $(NB_IPY) ; \
	  rc=$$?; if [ $$rc -eq 5 ]; then rc=0; fi; exit $$rc
	$(BIN)/ruff check .

test-fast: $(STAMP)
	VSLBOOK_BUDGET=smoke $(BIN)/python -m pytest -q -m "not slow" tests

lab: notebooks
	$(BIN)/jupyter lab notebooks/

lint: $(STAMP)
	$(BIN)/ruff check .

clean:
	rm -rf build notebooks/*.ipynb .pytest_cache
