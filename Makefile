# tfm: the README's two setup commands are `make install` and `make test`.
PYTHON ?= python3
NAME ?=
JOBS ?= $(shell nproc 2>/dev/null || echo 1)

.PHONY: help install test test-slow run bench bench-quick bench-scale validate rough paper limit campaign campaigns clean

help:               ## this list
	@grep -E '^[a-z-]+:.*##' Makefile | sed 's/:[^#]*## */\t/'

install:            ## install tfm and its test dependencies (editable)
	$(PYTHON) -m pip install -q -e ".[test]"

test:               ## the CI test suite (fast tier)
	$(PYTHON) -m pytest -q

test-slow:          ## paper-scale regression tests (minutes to hours)
	$(PYTHON) -m pytest -q -m slow

run:                ## the main job on its embedded default: the paper's Fig. 3 case
	mkdir -p results/default
	$(PYTHON) -m tfm run --overwrite -o results/default/curve.parquet

bench:              ## ratios against bench/baseline.py, before/after, operators, curves, tree (medians)
	$(PYTHON) -m bench.run_bench $(BENCH_FLAGS)

bench-quick:        ## the ratios without the 2-minute baseline run at 1/256
	$(PYTHON) -m bench.run_bench --only ratios --no-baseline-256

bench-scale:        ## scaling table 1/64 ... 1/1024, three runs each in turn (about 6 min): wall, solves, CG iterations, CPU/wall, threaded steps, peak RSS; medians
	$(PYTHON) -m bench.run_bench --scale

validate:           ## tfm against ContactMechanics (non-adhesive rough contact); pip install -e ".[validate]"
	$(PYTHON) -m bench.validate_contactmechanics

rough:              ## the rough-sphere campaign, then its figure and table in results/rough/
	$(PYTHON) -m tfm campaign run campaigns/rough_sphere.toml --jobs $(JOBS)
	$(PYTHON) -m bench.rough_report

campaign:           ## run campaigns/$(NAME).toml, e.g. make campaign NAME=smoke JOBS=2
	@test -n "$(NAME)" || (echo "usage: make campaign NAME=<file stem>; see make campaigns"; exit 2)
	$(PYTHON) -m tfm campaign run campaigns/$(NAME).toml --jobs $(JOBS)

campaigns:          ## list the campaign files
	@for f in campaigns/*.toml; do echo "$$(basename $$f .toml)"; done

paper:              ## every result of the paper: campaigns, figures, results/paper/REPORT.md
	$(PYTHON) -m tfm.paper --jobs $(JOBS)

limit:              ## beyond the paper: continuum limit of the pull-off coefficient, results/limit/REPORT.md
	$(PYTHON) -m tfm limit --jobs $(JOBS)

clean:
	rm -rf build dist *.egg-info .pytest_cache
