# Fresh machine: `make demo` runs the main job, `make test` runs the test suite.
# Each target creates .venv and installs graphloc first (scripts/bootstrap.sh).
VENV ?= .venv
STAMP := $(VENV)/.graphloc-installed
OUT ?= out

.PHONY: demo test test-all bench-p3p clean

$(STAMP): pyproject.toml setup.py scripts/bootstrap.sh
	VENV=$(VENV) bash scripts/bootstrap.sh
	touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/graphloc demo --out $(OUT)/demo

test: $(STAMP)
	$(VENV)/bin/python -m pytest --durations=20

test-all: $(STAMP)
	$(VENV)/bin/python -m pytest -m "slow or not slow" --durations=20

bench-p3p: $(STAMP)
	$(VENV)/bin/python scripts/bench_p3p.py --out $(OUT)/bench_p3p

clean:
	rm -rf $(VENV) $(OUT) build dist *.egg-info
