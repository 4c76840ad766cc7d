# Every target installs what is missing first (scripts/setup.sh is idempotent).
PYTHON := .venv/bin/python
AQUAROM := .venv/bin/aquarom
OUT ?= results/demo

.PHONY: setup demo test docs bench validate validate-radius study clean docker-test

setup:
	@bash scripts/setup.sh

demo: setup
	$(PYTHON) scripts/demo.py --out $(OUT)

test: setup
	$(PYTHON) -m pytest -q -ra tests

bench: setup
	$(PYTHON) scripts/bench_fom.py
	$(PYTHON) scripts/bench_prom.py
	$(PYTHON) scripts/bench_optimize.py

study: setup
	$(PYTHON) scripts/study.py

validate: setup
	$(PYTHON) scripts/validate.py --jobs 2

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
