# `make demo` and `make test` each do all the set-up on a fresh machine, then run.
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
export MUJOCO_GL := egl
export PYTHONUNBUFFERED := 1

.PHONY: setup debs demo test bench lint format train

$(STAMP): pyproject.toml
	test -x $(PY) || python3 -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q torch==2.13.0   # the CPU build; must come before anything needing torch
	$(PY) -m pip install -q -e '.[test,ray]'
	touch $(STAMP)

setup: $(STAMP) debs

# Debian packages: EGL for headless MuJoCo, Chromium for the browser tests.
debs:
	@missing=""; \
	for p in libegl1 libgl1-mesa-dri libgles2 chromium fonts-dejavu-core; do \
	  dpkg -s $$p >/dev/null 2>&1 || missing="$$missing $$p"; done; \
	if [ -n "$$missing" ]; then \
	  echo "installing Debian packages:$$missing"; \
	  SUDO=$$( [ "$$(id -u)" = 0 ] || echo sudo ); \
	  $$SUDO apt-get update -qq && $$SUDO apt-get install -y -qq --no-install-recommends $$missing; \
	fi

train: setup
	$(VENV)/bin/dfa train

demo: setup
	$(VENV)/bin/dfa demo

test: setup
	$(PY) -m pytest -x -q

bench: setup
	$(VENV)/bin/dfa bench

lint: setup
	$(PY) -m ruff check .
	$(PY) -m ruff format --check .

format: setup
	$(PY) -m ruff format .
	$(PY) -m ruff check --fix .
