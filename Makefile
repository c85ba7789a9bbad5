# Set-up and main entry points. `make demo` and `make test` both work on a fresh clone.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test lint bench clean venv docs pip-check

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[dev,docs]'
	$(BIN)/python -c "from irreflect.fitting import warm; warm()"  # compile the fitting kernel once
	$(BIN)/python -c "from irreflect.room.warm import warm; warm()"  # and the room kernels
	touch $(STAMP)

venv: $(STAMP)

demo: $(STAMP)
	$(BIN)/irreflect reproduce --out out --scene office
	$(BIN)/irreflect room office --out out/room --workers 2

test: $(STAMP)
	$(BIN)/python -m pytest -q -n 2 --dist loadfile

lint: $(STAMP)
	$(BIN)/ruff check src tests experiments

docs: $(STAMP)
	$(BIN)/mkdocs build --strict --site-dir build/site

pip-check: $(STAMP)
	$(BIN)/python .ci/pip_install_check.py

bench: $(STAMP)
	$(BIN)/python experiments/bench_fit.py
	$(BIN)/python experiments/bench_single_fit.py
	$(BIN)/python experiments/bench_select.py
	$(BIN)/python experiments/bench_room.py

clean:
	rm -rf $(VENV) out build src/*.egg-info .pytest_cache
