# id_learning quick start: `make demo` runs the main job on bags/, `make test` runs the tests
# (after mypy and `make docs`, which builds the manual in docs/ into build/docs).
# Both create .venv when it is missing. With ROS 2 Jazzy installed from apt (sourced or under
# /opt/ros/jazzy) the venv sees the system's rclpy; otherwise ROS 2 Jazzy comes from PyPI wheels.
# Settings are taken from the command line only (`make demo DEMO_BAG=... DEMO_OUT=...`), never
# from the environment: a shell's OUT or BAG must not redirect where the demo writes.
SHELL := /bin/bash
VENV := .venv
PY := $(VENV)/bin/python
DEMO_BAG := bags/default
DEMO_OUT := out/demo
# The reference study's Table 1 (not part of the package), placed beside ours when present.
STUDY_TABLE := $(wildcard ../shared/data/study_table1/table1.json)
ifneq ($(filter command line,$(origin BAG) $(origin OUT)),)
$(error BAG and OUT are now DEMO_BAG and DEMO_OUT: make demo DEMO_BAG=path/to/bag DEMO_OUT=out/other)
endif

.PHONY: demo test test-long lint typecheck docs venv clean bag

venv: $(VENV)/.ready

$(VENV)/.ready: tools/bootstrap_venv.sh requirements.txt pyproject.toml setup.py
	bash tools/bootstrap_venv.sh $(VENV)
	touch $@

demo: venv
	source tools/env.sh $(VENV) && $(PY) -m id_learning.cli demo --bag $(DEMO_BAG) --out $(DEMO_OUT) --force \
		$(if $(STUDY_TABLE),--study-table $(STUDY_TABLE))

# pytest exits 5 when it collects no test: make treats that as the failure it is.
test: venv typecheck docs
	source tools/env.sh $(VENV) && $(PY) -m pytest -q test -m 'not long' $(PYTEST_ARGS)

# The whole-model diagnosis cases of a minute and more each (about 8 min on 2 cores).
test-long: venv
	source tools/env.sh $(VENV) && $(PY) -m pytest -q test -m long $(PYTEST_ARGS)

# mypy over id_learning/ (settings in pyproject.toml); `make test` runs it first.
typecheck: venv
	source tools/env.sh $(VENV) && $(PY) -m mypy

# The manual (Sphinx + myst-parser, docs/conf.py) into build/docs: warnings are errors, every page
# read afresh (-E) so that none is skipped; no network. `make test` builds it first.
docs: venv
	source tools/env.sh $(VENV) && $(PY) -m sphinx -b html -E -q -W --keep-going docs build/docs

lint: venv
	$(VENV)/bin/ruff check . && $(VENV)/bin/ruff format --check .

bag: venv
	source tools/env.sh $(VENV) && $(PY) -m id_learning.cli simulate --config config/twin_default.yaml --out $(DEMO_BAG) --force

clean:
	rm -rf out build install log docs/api/generated
