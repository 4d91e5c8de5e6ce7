# Two commands on a fresh machine (see README):  `make demo`  and  `make test`.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
OUT    ?= out

.PHONY: install demo test lint bench clean

$(BIN)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	touch $@

install: $(BIN)/.installed

# The main job: a generated Carolo-Cup track, validated, with its preview PNG.
demo: install
	$(BIN)/tfalda-sim track generate --seed 7 --out $(OUT)/track-7.json --png $(OUT)/track-7.png --force

# The test command CI runs (.ci/run): lint, then the whole test suite.
test: install
	$(BIN)/ruff check .
	$(BIN)/python -m pytest -q

bench: install
	$(BIN)/python benchmarks/bench_tracks.py
	$(BIN)/python benchmarks/bench_render.py
	$(BIN)/python benchmarks/bench_perception.py

clean:
	rm -rf $(VENV) $(OUT) .pytest_cache .ruff_cache
