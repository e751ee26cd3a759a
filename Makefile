# dvrk_dart: every target creates the virtual environment itself when missing.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
OUT    ?= out
RUNS   ?= $(OUT)/runs
REPORT ?= report
JOBS   ?= 2
# Python writes its bytecode caches (.venv, dvrk_dart/__pycache__) the first time
# it imports a module: with PYTHONDONTWRITEBYTECODE set (some shells and CI
# images do) and pip's --no-compile, every process (test workers, the CLI
# subprocesses, validate's workers) compiled every imported module again: ~2.5 s each
unexport PYTHONDONTWRITEBYTECODE

.PHONY: validate test bench report check-report view clean setup docs help

help:
	@echo "make validate      the whole validation campaign, then the report ($(OUT), $(REPORT)/index.html)"
	@echo "make test          the tests, JOBS=$(JOBS) side by side"
	@echo "make bench         performance figures against their targets ($(OUT)/bench.json)"
	@echo "make docs          the documentation site (site/), figures from the last validation"
	@echo "make report        the report of the runs in RUNS=$(RUNS)"
	@echo "make check-report  the report's browser test"
	@echo "make view RUN=DIR  a run in the Rerun viewer (DIR/run.rrd)"
	@echo "make setup         the virtual environment ($(VENV)); every target makes it when missing"
	@echo "make clean         remove $(OUT), $(REPORT), site and the project's bytecode caches"

setup: $(STAMP)

# --no-compile: Python compiles what it imports; byte-compiling every installed package doubled the setup
$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q --no-compile -e ".[test]"
	touch $(STAMP)

## The main job: the whole validation campaign, then the report.
validate: $(STAMP)
	$(BIN)/dvrk-dart validate --out $(OUT) --report $(REPORT) --jobs $(JOBS)

## the tests, JOBS side by side (pytest-xdist; a module's tests on one worker, so its fixtures are made once)
test: $(STAMP)
	$(BIN)/python -m pytest -q -n $(JOBS) --dist loadscope

bench: $(STAMP)
	$(BIN)/python -m dvrk_dart.bench --out $(OUT)/bench.json

## the documentation site (docs/, mkdocs.yml) -> site/; figures from the last validation in $(OUT)
docs: $(STAMP)
	DVRK_DART_OUT=$(OUT) NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict -q
	@echo "docs: site/index.html"

report: $(STAMP)
	$(BIN)/dvrk-dart report --runs $(RUNS) --out $(REPORT)

check-report: $(STAMP)
	$(BIN)/python -m pytest -q tests/test_report_browser.py

## make view RUN=out/runs/<run-name>
view: $(STAMP)
	@test -n "$(RUN)" || { echo "make view: give RUN=out/runs/<run-name> (a folder holding run.rrd)"; exit 2; }
	@test -f "$(RUN)/run.rrd" || { echo "make view: $(RUN)/run.rrd: no such file"; exit 2; }
	$(BIN)/rerun $(RUN)/run.rrd

clean:
	rm -rf $(OUT) $(REPORT) site .pytest_cache
	find . -path ./$(VENV) -prune -o -name __pycache__ -type d -prune -exec rm -rf {} +  # the venv's caches stay (2.5 s a process)
