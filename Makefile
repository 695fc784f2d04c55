# gesturelib: the commands of the README. Each target sets itself up when needed
# (a virtual environment in .venv with the tested versions of requirements-lock.txt)
# and is fast when that is already done.

PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
# Extra pip arguments for the PyTorch install only, e.g. an index of CPU-only wheels on a Linux
# laptop without a GPU (see the README). Empty by default.
TORCH_PIP_ARGS ?=
TORCH_VERSION := $(shell sed -n 's/^torch==//p' requirements-lock.txt)
STAMP := $(VENV)/.installed
OUT ?= outputs/demo

.PHONY: setup demo test check-full results lab lint benchmark lock clean

setup: $(STAMP)

$(STAMP): requirements-lock.txt pyproject.toml
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	@# PyTorch first and on its own, so that TORCH_PIP_ARGS can pick a CPU-only build.
	$(BIN)/python -m pip install --quiet $(TORCH_PIP_ARGS) "torch==$(TORCH_VERSION)"
	$(BIN)/python -m pip install --quiet -r requirements-lock.txt
	$(BIN)/python -m pip install --quiet --no-deps -e .
	@touch $(STAMP)

## make demo: generate a short conversation and render it (video with sound) into $(OUT)
demo: setup
	$(BIN)/python -m gesturelib demo --out $(OUT)

## make test: lint, format check, unit tests and every notebook executed in quick mode
test: setup
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	@# On every core: a notebook's cells stay together, in order, on one worker (loadscope);
	@# the notebooks, the longest work, are handed out first.
	GESTURELIB_QUICK=1 MPLBACKEND=Agg $(BIN)/python -m pytest notebooks tests \
		--nbval-lax --nbval-current-env --nbval-cell-timeout=300 -n auto --dist loadscope

## make check-full: every notebook executed in full mode, its claims asserted, then its exercises'
## solutions (NB=04 for one); the executed copies, with their pictures, go to outputs/check-full/.
## Not part of CI (minutes to hours).
NB ?=
check-full: setup
	$(BIN)/python tools/check_full.py $(NB)

## make results: every model from three seeds against the references, and MoGlow's style
## control (full mode, about two hours the first time); writes outputs/results/ and the
## README's results tables
results: setup
	$(BIN)/python tools/results.py

## make lab: open JupyterLab on the notebooks (as root too: containers and Binder run as root)
lab: setup
	$(BIN)/jupyter lab notebooks $(if $(filter 0,$(shell id -u)),--allow-root)

## make benchmark: the speed figures quoted in the README
benchmark: setup
	for script in benchmarks/bench_*.py; do $(BIN)/python $$script || exit 1; done

## make lock: record the exact versions of the current environment as the tested set
lock:
	$(BIN)/python -m pip freeze --exclude-editable | sed 's/^torch==\([0-9.]*\)+.*/torch==\1/' \
		> requirements-lock.txt

clean:
	rm -rf $(VENV) outputs .pytest_cache
