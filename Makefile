# vslbook: two commands.
#   make book   set up .venv and build the book site into build/site/: the figures read the
#               recorded results of data/results/ (or finished runs in runs/; smoke runs
#               trained now where neither exists), the rest executes at reduced.
#               VSLBOOK_BUDGET=B trains what B lacks (build/site-B/); RETRAIN=1 trains
#               every run of the budget, after printing the core-hours (vslbook plan).
#   make test   set up .venv and run the tests, notebooks and the site's browser test
#               included, at the smoke budget
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
# The site typesets math with a MathJax copy it serves itself (offline); npm fetches it once.
MATHJAX_VERSION := 3.2.2
MATHJAX := $(VENV)/mathjax/node_modules/mathjax/es5/tex-chtml.js
# The site's browser test drives Debian's chromium (with an emoji font: the notebooks' check
# reports mark results with ✅ / ❌, and the screenshots should show what a reader sees).
CHROMIUM ?= /usr/bin/chromium
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)
# Offscreen MuJoCo pictures (the tasks page, Fig. 3.3) use Mesa's OSMesa (MUJOCO_GL=osmesa).
GL_PKGS := libosmesa6
NB_SRC := $(sort $(wildcard notebooks/[0-9][0-9]_*.py))
NB_IPY := $(NB_SRC:.py=.ipynb)
VSLBOOK_BUDGET ?=
RETRAIN ?=
export MPLBACKEND ?= Agg
export MUJOCO_GL ?= disable
export PYTHONHASHSEED := 0
# stable-baselines3 makes a fresh folder tempdir/SB3-<time> whenever PPO.learn runs without
# a logger set (the library sets one; a few tests call learn directly); one folder under
# build/ keeps /tmp clean.
export SB3_LOGDIR ?= $(CURDIR)/build/sb3-logs

.PHONY: setup myo book site test test-fast notebooks lab lint clean help browser gl
.DEFAULT_GOAL := help

help:
	@echo "make book   build the book site from recorded results into build/site/"
	@echo "            (VSLBOOK_BUDGET=smoke|reduced|full: that budget; RETRAIN=1: train it all)"
	@echo "make test   run the test suite, notebooks and the site browser test included (smoke budget)"
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

$(MATHJAX): | $(BIN)/python
	@command -v npm >/dev/null 2>&1 || { echo "need npm (Node.js) to fetch MathJax $(MATHJAX_VERSION)"; exit 1; }
	npm install --prefix $(VENV)/mathjax --no-save --no-audit --no-fund --loglevel=error \
	  mathjax@$(MATHJAX_VERSION)

$(CHROMIUM):
	$(SUDO) apt-get update -qq
	DEBIAN_FRONTEND=noninteractive $(SUDO) apt-get install -y -qq chromium fonts-noto-color-emoji >/dev/null

browser: $(CHROMIUM)

# tests/test_slurm_sweep.py starts a one-node SLURM (munged, slurmctld, slurmd on 127.0.0.1)
# from Debian's packages; their system services are not used.
SLURM_PKGS := slurm-wlm munge
slurm:
	@command -v slurmctld >/dev/null 2>&1 && command -v munged >/dev/null 2>&1 || { \
	  command -v apt-get >/dev/null 2>&1 || { echo "no apt-get: install SLURM and MUNGE ($(SLURM_PKGS)) yourself"; exit 0; }; \
	  $(SUDO) apt-get update -qq && \
	  DEBIAN_FRONTEND=noninteractive $(SUDO) apt-get install -y -qq $(SLURM_PKGS) >/dev/null; }

gl:
	@command -v dpkg >/dev/null 2>&1 || { echo "not a Debian system: install Mesa's OSMesa ($(GL_PKGS)) yourself"; exit 0; }; \
	dpkg -s $(GL_PKGS) >/dev/null 2>&1 || { $(SUDO) apt-get update -qq && \
	  DEBIAN_FRONTEND=noninteractive $(SUDO) apt-get install -y -qq $(GL_PKGS) >/dev/null; }

setup: $(STAMP) $(MATHJAX) gl

# MyoSuite's hand tasks alone (already part of setup); --no-deps keeps the pinned stack.
myo: | $(BIN)/python
	$(BIN)/python -m pip install --quiet --no-deps $(MYO)

notebooks/%.ipynb: notebooks/%.py $(STAMP)
	$(BIN)/jupytext --quiet --to ipynb --output $@ $<

notebooks: $(NB_IPY)

# The site: Sphinx + MyST-NB executes each notebook at the budget (cached per budget, so an
# unchanged notebook is not run again) and ends by printing the page to open.
book: setup
	VSLBOOK_FIGURES=$(CURDIR)/build/figures $(BIN)/python book/build.py \
	  $(if $(VSLBOOK_BUDGET),--budget $(VSLBOOK_BUDGET)) $(if $(RETRAIN),--retrain)

site: book

# make test runs in two lanes, one per core of a 2-core machine:
#   1. pytest over tests/ (the site's browser test last: tests/conftest.py);
#   2. in the background, the smoke site for the browser test (tests/site_build.py, its
#      output in build/site-smoke.log), then a second pytest over the notebooks (nbmake)
#      and LANE2_TESTS (the crash harness and DIME's seed-axis tests: test files with many
#      long tests, moved here so that the lanes end at about the same time), its output
#      in build/test-lane2.log, printed at the end.
# The notebooks run after the site's build, so they reuse the smoke runs it trained and
# never train one at the same time as it. pytest exits 5 when nothing is collected; that is
# not a failure of the suite. Each process runs one thread unless $OMP_NUM_THREADS says
# otherwise: two threads each on two cores only contend.
SITE_STATUS := $(CURDIR)/build/site-smoke.status
LANE2_LOG := $(CURDIR)/build/test-lane2.log
LANE2_TESTS := tests/test_crash_resume.py tests/test_dime_seeds.py
test: notebooks $(MATHJAX) gl browser slurm
	mkdir -p build && rm -f $(SITE_STATUS) $(LANE2_LOG)
	export OMP_NUM_THREADS=$${OMP_NUM_THREADS:-1} VSLBOOK_SITE_BUILD=$(SITE_STATUS) \
	  VSLBOOK_BUDGET=smoke VSLBOOK_FIGURES=$(CURDIR)/build/figures-smoke; \
	( $(BIN)/python tests/site_build.py $(SITE_STATUS); \
	  $(BIN)/python -m pytest -q -p no:cacheprovider --durations=10 --nbmake \
	    --nbmake-timeout=2400 $(NB_IPY) $(LANE2_TESTS) > $(LANE2_LOG) 2>&1 ) & \
	lane2=$$!; \
	$(BIN)/python -m pytest -q --durations=15 tests $(LANE2_TESTS:%=--ignore=%); rc=$$?; \
	wait $$lane2; rc2=$$?; \
	echo "== lane 2: the notebooks and $(LANE2_TESTS), after the site's build ($(LANE2_LOG))"; \
	cat $(LANE2_LOG); \
	if [ $$rc -eq 5 ]; then rc=0; fi; if [ $$rc2 -eq 5 ]; then rc2=0; fi; \
	if [ $$rc -ne 0 ]; then exit $$rc; fi; exit $$rc2
	$(BIN)/ruff check .

test-fast: $(STAMP)
	VSLBOOK_BUDGET=smoke $(BIN)/python -m pytest -q -m "not slow" tests

lab: notebooks
	$(BIN)/jupyter lab notebooks/

lint: $(STAMP)
	$(BIN)/ruff check .

clean:
	rm -rf build notebooks/*.ipynb .pytest_cache
