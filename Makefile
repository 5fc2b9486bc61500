# Two commands for a user: `make book` and `make test`. Everything runs inside .venv, which is
# created from the pinned requirements.txt on first use (pip only, works offline where the
# package files are cached).
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV   ?= .venv
PY     := $(VENV)/bin/python
JOBS   ?= 2
STAMP  := $(VENV)/.installed

.PHONY: venv book api chapter study claims parity ladder test test-fast lint format bench clean help

help:
	@echo "make book      run every chapter (smoke profile) and build the HTML book"
	@echo "make test      run the whole test suite (what CI runs)"
	@echo "make api       build only the API reference page (no notebooks; _build/api/)"
	@echo "make chapter CHAPTER=01_background [PROFILE=full]   run one chapter"
	@echo "make study CHAPTER=04_hdt [JOBS=2]   run or resume a pre-registered study"
	@echo "make claims    studies/claims.csv from the committed studies"
	@echo "make parity [ONLY='dt-study bc-study']   our DT/BC against d3rlpy's (params/parity.yml)"
	@echo "make ladder [RUNGS=d32L1]               the sequence models' scale ladder (params/ladder.v2.yml)"
	@echo "make test-fast unit tests only (no notebook runs, no book build)"
	@echo "make lint      ruff (lint + format check) and the type checker"
	@echo "make format    ruff format + safe fixes"
	@echo "make bench     run every benchmark in benchmarks/"
	@echo "make clean     remove generated notebooks, results and the built book"

$(STAMP): requirements.txt pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -r requirements.txt
	$(PY) -m pip install --no-deps -e .
	touch $(STAMP)

venv: $(STAMP)

book: $(STAMP)
	$(VENV)/bin/thesis book -j $(JOBS)

# The API reference alone, with the book's settings and -W -n like `make book`: a one-page toc.
api: $(STAMP)
	mkdir -p _build
	printf 'format: jb-book\nroot: book/api\n' > _build/api_toc.yml
	$(VENV)/bin/jupyter-book build . --toc $(CURDIR)/_build/api_toc.yml --path-output $(CURDIR)/_build/api -W -n --keep-going

chapter: $(STAMP)
	$(VENV)/bin/thesis run $(CHAPTER) --profile $(or $(PROFILE),smoke)

study: $(STAMP)
	nice $(VENV)/bin/thesis study $(CHAPTER) -j $(JOBS)

claims: $(STAMP)
	$(VENV)/bin/thesis claims

# Peer parity: makes the peer venv (d3rlpy 2.8.1) under $THESIS_CACHE_DIR once, runs what is
# missing of params/parity.yml (or only ONLY's comparisons), writes studies/parity/parity.csv.
parity: $(STAMP)
	$(VENV)/bin/thesis parity --setup
	nice $(VENV)/bin/thesis parity -j $(JOBS) $(if $(ONLY),--only $(ONLY))

# The sequence models' scale ladder (issue #36): runs what is missing of params/ladder.v2.yml
# (or only RUNGS', e.g. RUNGS=d32L1), writes studies/ladder.v2/ladder.csv and the chosen size.
ladder: $(STAMP)
	nice $(VENV)/bin/thesis ladder -j $(JOBS) $(if $(RUNGS),--rungs $(RUNGS))

# The tests run in $(JOBS) pytest-xdist workers, a test file to a worker (--dist loadfile: a
# file's module fixtures are made once, and the chapter runs of test_chapters.py stay on one
# worker, which runs them 2 at a time, longest first). --no-loadscope-reorder hands the files
# out in collection order, where tests/conftest.py puts test_chapters.py first: the chapter
# runs start at once. `pytest` alone runs them in one process.
XDIST := -n $(JOBS) --dist loadfile --no-loadscope-reorder
test: $(STAMP)
	$(PY) -m pytest $(XDIST)

test-fast: $(STAMP)
	$(PY) -m pytest $(XDIST) -m "not slow"

LINT_PATHS := src tests benchmarks notebooks book/_ext

lint: $(STAMP)
	$(VENV)/bin/ruff check $(LINT_PATHS)
	$(VENV)/bin/ruff format --check $(LINT_PATHS)
	$(VENV)/bin/mypy

format: $(STAMP)
	$(VENV)/bin/ruff format $(LINT_PATHS)
	$(VENV)/bin/ruff check --fix $(LINT_PATHS)

bench: $(STAMP)
	for f in benchmarks/bench_*.py; do echo "== $$f"; $(PY) $$f || exit 1; done

clean:
	rm -rf _build book/generated results/*/
