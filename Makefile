# Every target installs what is missing first (scripts/setup.sh is idempotent).
# `make validate SCHEDULER=tcp://host:8786` (or SCHEDULER_FILE=FILE) computes on a Dask cluster; so does `make study`.
PYTHON := .venv/bin/python
AQUAROM := .venv/bin/aquarom
OUT ?= results/demo

.PHONY: setup demo test docs bench validate validate-radius study clean docker-test

setup:
	@bash scripts/setup.sh

demo: setup
	$(PYTHON) scripts/demo.py --out $(OUT)

# One BLAS thread per test process: the two xdist workers already take both cores.
test: setup
	OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 $(PYTHON) -m pytest -q -ra -n 2 --dist loadfile tests

bench: setup
	$(PYTHON) scripts/bench_fom.py
	$(PYTHON) scripts/bench_prom.py
	$(PYTHON) scripts/bench_optimize.py
	$(PYTHON) scripts/bench_sweep.py
	$(PYTHON) scripts/validate_atlas.py --sweep-only

study: setup
	$(PYTHON) scripts/study.py $(if $(SCHEDULER),--scheduler $(SCHEDULER)) $(if $(SCHEDULER_FILE),--scheduler-file $(SCHEDULER_FILE))

validate: setup
	$(PYTHON) scripts/validate.py --jobs 2 $(if $(SCHEDULER),--scheduler $(SCHEDULER)) $(if $(SCHEDULER_FILE),--scheduler-file $(SCHEDULER_FILE))

validate-radius: setup
	$(PYTHON) scripts/validate_prom_radius.py

clean:
	rm -rf results meshes/cache .pytest_cache

# Not part of `test`: needs a Docker daemon and a debian:bookworm image (docker/README.md).
docker-test: setup
	@$(PYTHON) scripts/docker_test.py

# The manual (Sphinx, warnings are errors) into docs/_build/html.
docs: setup
	$(PYTHON) -m sphinx -W --keep-going -b html docs docs/_build/html
