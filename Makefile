# Two commands on a fresh machine (see README):  `make demo`  and  `make test`.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
OUT    ?= out

.PHONY: install demo test lint bench evaluation-docs clean

$(BIN)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	# torch first, pinned to the local CPU wheel, so that stable-baselines3 (the rl extra)
	# never makes pip fetch another torch with gigabytes of CUDA.
	$(BIN)/python -m pip install --quiet torch==2.13.0
	$(BIN)/python -m pip install --quiet -e '.[dev,rl,ray,rllib]'
	# numba's on-disk cache pickles the module name of each kernel: entries compiled before
	# a package moved (tracks -> tfalda_sim.tracks) would name a module that is gone.
	find tfalda_sim tracks envs agents -name '*.nb[ic]' -delete
	touch $@

install: $(BIN)/.installed

# The main job: the PID drives 2 laps of generated track seed 7 from the camera alone;
# an MP4 of the drive and the lap summary.
demo: install
	$(BIN)/tfalda-sim drive --agent pid --track 7 --laps 2 --video $(OUT)/drive-7.mp4 --force

# The test command CI runs (.ci/run): lint, the import contracts, the whole test suite.
test: install
	$(BIN)/ruff check .
	$(BIN)/python tools/lint_imports.py
	$(BIN)/python -m pytest -q

# Every main benchmark with --json into benchmarks/results/, then BENCHMARKS.md from them
# (one: $(BIN)/python benchmarks/report.py --run bench_env).
bench: install
	$(BIN)/python benchmarks/report.py --run

# The charts and figures of docs/evaluation.md (about 5 min on 2 cores).
EV = docs/evaluation
evaluation-docs: install
	for s in straight curve track; do \
	  $(BIN)/tfalda-sim evaluate --scenario $$s --plot $(EV)/$$s.png --json --force > $(EV)/$$s.json || exit 1; \
	done
	$(BIN)/tfalda-sim evaluate --scenario track --preset improved --plot $(EV)/track-improved.png --json --force > $(EV)/track-improved.json
	$(BIN)/tfalda-sim evaluate --scenario random --seeds 0:50 --plot $(EV)/random-0-50.png --json --force > $(EV)/random-0-50.json
	$(BIN)/tfalda-sim evaluate --scenario random --seeds 0:50 --ablation --plot $(EV)/ablation-0-50.png --json --force > $(EV)/ablation-0-50.json
	$(BIN)/tfalda-sim evaluate --scenario random --seeds 0:50 --ablation --preset improved --plot $(EV)/ablation-improved-0-50.png --json --force > $(EV)/ablation-improved-0-50.json

clean:
	rm -rf $(VENV) $(OUT) .pytest_cache .ruff_cache
	find tfalda_sim tracks envs agents -name '*.nb[ic]' -delete
