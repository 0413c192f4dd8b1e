# tfm: the README's two setup commands are `make install` and `make test`.
PYTHON ?= python3
NAME ?=
JOBS ?= $(shell nproc 2>/dev/null || echo 1)

.PHONY: install test test-slow run bench paper campaign campaigns clean

install:            ## install tfm and its test dependencies (editable)
	$(PYTHON) -m pip install -q -e ".[test]"

test:               ## the CI test suite (fast tier)
	$(PYTHON) -m pytest -q

test-slow:          ## paper-scale regression tests (minutes to hours)
	$(PYTHON) -m pytest -q -m slow

run:                ## the main job on its embedded default: the paper's Fig. 3 case
	tfm run --overwrite -o results/default/curve.parquet

bench:              ## operator and full-curve benchmarks (medians; prints the machine)
	$(PYTHON) -m bench.run_bench

campaign:           ## run campaigns/$(NAME).toml, e.g. make campaign NAME=smoke JOBS=2
	@test -n "$(NAME)" || (echo "usage: make campaign NAME=<file stem>; see make campaigns"; exit 2)
	tfm campaign run campaigns/$(NAME).toml --jobs $(JOBS)

campaigns:          ## list the campaign files
	@for f in campaigns/*.toml; do echo "$$(basename $$f .toml)"; done

paper:              ## every result of the paper: campaigns, figures, results/paper/REPORT.md
	$(PYTHON) -m tfm.paper --jobs $(JOBS)

clean:
	rm -rf build dist *.egg-info .pytest_cache
