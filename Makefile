# SLZ Lander: two commands do all set-up. `make demo` runs the main job, `make test` runs the checks.
# Both create the virtualenv idempotently from the lock (re-installed only when the lock or pyproject.toml changes):
# requirements/dev.lock pins every distribution with its hashes, so a fresh machine installs what was tested.
# `make lock` rewrites the locks (scripts/lock.py, uv), `make lock-upgrade` moves them to the newest releases, and
# `make test-latest` runs the whole suite on the newest releases without touching the lock.

PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed-stamp
LOCK := requirements/dev.lock
# LOCKED=0 installs the newest releases pyproject.toml allows instead of the lock (`make test-latest`).
LOCKED ?= 1
LATEST_VENV := .venv-latest

.PHONY: setup demo test test-latest test-slow lock lock-upgrade lockcheck lint typecheck pytest bench paper-table \
	paper-table-roi eval-real eval-tradeoff training models clean

setup: $(STAMP)

ifeq ($(LOCKED),1)
$(STAMP): pyproject.toml $(LOCK) scripts/install-system-deps.sh
	bash scripts/install-system-deps.sh
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --require-hashes --no-deps -r $(LOCK)
	$(BIN)/python -m pip install --quiet --no-deps --no-build-isolation -e .
	$(BIN)/python -m pip check
	$(BIN)/python scripts/lock.py check $(LOCK)
	@touch $(STAMP)
else
$(STAMP): pyproject.toml scripts/install-system-deps.sh
	bash scripts/install-system-deps.sh
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade --upgrade-strategy eager pip 'setuptools>=77' wheel -e '.[dev]'
	$(BIN)/python -m pip check
	@touch $(STAMP)
endif

demo: $(STAMP)
	$(BIN)/slz demo --out runs

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

typecheck: $(STAMP)
	$(BIN)/mypy companion sitl bench tests models scripts

# pytest exits 5 when it collected no test: make treats that as a failure, as it must. --durations: the CI log
# names the slowest tests, to keep the suite well under 15 minutes on 2 cores.
pytest: $(STAMP)
	$(BIN)/python -m pytest -m "not slow" --durations=15

# The environment is the lock's, exactly (nothing upgraded or added by hand since `make setup`).
lockcheck: $(STAMP)
ifeq ($(LOCKED),1)
	$(BIN)/python scripts/lock.py check $(LOCK)
else
	$(BIN)/python scripts/lock.py check --report $(LOCK)
endif

test: lockcheck lint typecheck pytest

# The whole suite on the newest releases pyproject.toml allows, in its own virtualenv (re-resolved at every run),
# after a list of what differs from the lock. A failure here is an upgrade to decide on, not a broken main.
test-latest:
	rm -f $(LATEST_VENV)/.installed-stamp
	$(MAKE) test VENV=$(LATEST_VENV) LOCKED=0

# Rewrite requirements/*.lock after a change to pyproject.toml (locked versions kept where they still fit), or move
# every lock to the newest releases (then `make setup test`, and commit the locks with what the upgrade needed).
lock: $(STAMP)
	$(BIN)/python scripts/lock.py compile

lock-upgrade: $(STAMP)
	$(BIN)/python scripts/lock.py compile --upgrade

# The slow tier: the tests too long for every run (the MAVSDK square at real speed, `slz campaign replay`).
# The nightly workflow runs them.
test-slow: $(STAMP)
	$(BIN)/python -m pytest -m slow

bench: $(STAMP)
	$(BIN)/python -m bench.perception
	$(BIN)/python -m bench.sitl_speed
	$(BIN)/python -m bench.render
	$(BIN)/python -m bench.density
	$(BIN)/python -m bench.companion_latency
	$(BIN)/python -m bench.sitl_fuzz
	$(BIN)/python -m bench.hostile_configs

# The paper's Table I at 100 runs per cell (900 missions; resumable: run it again to continue).
paper-table: $(STAMP)
	$(BIN)/slz campaign --spec mission_configs/campaigns/paper_table1.yaml --out runs/campaigns/paper_table1

# The same table with every zone held to the 30 m region of interest, as the paper's missions are (same scenes).
paper-table-roi: $(STAMP)
	$(BIN)/slz campaign --spec mission_configs/campaigns/paper_table1_roi.yaml --out runs/campaigns/paper_table1_roi

# Real aerial frames (every set under ../shared/datasets, evaluation only): person recall, false-occupied ground and
# count ratio at native and half scale, each shipped model beside the others on the same frames, in one run.
# The real ground of every site in sitl/world/ground: all frames of a site a model never trained on (its metadata
# names those it did). Writes models/eval/results/real.{json,md}; overlays under runs/eval/real/.
EVAL_REAL_MODELS ?= --model slz-lite=models/density/slz_lite.onnx --model slz-lite-int8=models/density/slz_lite_int8.onnx \
	--model slz-ccnn=models/density/slz_ccnn.onnx --model slz-lite-wide-real=models/density/slz_lite_wide_real.onnx
eval-real: $(STAMP)
	$(BIN)/python -m models.eval.real $(EVAL_REAL_MODELS) --out models/eval/results/real

# A diagnostic, never a way to choose a threshold (SDD is a test set): each model's person recall against its
# false-occupied ground over a grid of thresholds on the real sets with annotated people, and the false-occupied
# share at the highest threshold that still finds 97 % of them. Writes models/eval/results/tradeoff.{json,md}.
eval-tradeoff: $(STAMP)
	$(BIN)/python -m models.eval.tradeoff $(EVAL_REAL_MODELS) --out models/eval/results/tradeoff

# Optional: PyTorch for training (CPU build, pinned), then the whole density-model build (data, training, export,
# quantization, evaluation, ablations; about two hours on 2 cores). The drone needs neither.
training: $(STAMP)
	$(BIN)/python -m pip install --quiet --require-hashes --no-deps -r requirements/training.lock
	$(BIN)/python scripts/lock.py check requirements/training.lock

models: training
	bash scripts/build-density-models.sh

clean:
	rm -rf $(VENV) $(LATEST_VENV) .mypy_cache .ruff_cache .pytest_cache runs
