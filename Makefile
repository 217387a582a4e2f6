# The few commands everyone runs. `make demo` and `make test` each install what they need.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test lint bench clean

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/btrack sim --robots 3 --map half-algae --start ahead:1 --out runs/demo

# Two workers, each taking whole files (a module's team fixture runs once): most tests
# wait on processes of their own, so two at a time keep two cores busy.
TEST_WORKERS ?= 2

test: $(STAMP)
	$(BIN)/python -m pytest -q -n $(TEST_WORKERS) --dist loadfile

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/mypy agent wire localizer hwbridge deploy report recorder simworld btrack scene replay
	$(BIN)/mypy bench  # apart: bench/localizer.py would clash with the localizer package

bench: $(STAMP)
	$(BIN)/python bench/speed.py

clean:
	rm -rf $(VENV) runs .pytest_cache .ruff_cache .mypy_cache
