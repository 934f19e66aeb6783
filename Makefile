# `make demo` and `make test` each do all the set-up on a fresh machine, then run.
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
LOCK   := requirements.lock
export MUJOCO_GL := egl
export PYTHONUNBUFFERED := 1

.PHONY: setup debs demo test bench lint format train lock

# torch first (the CPU build, from a file on local disk through pip's configuration; it is kept
# out of the lock because that file's hash is not the registry's), then every other package at
# the locked version with its hash checked, then the project itself. Nothing resolves here.
$(STAMP): pyproject.toml $(LOCK)
	test -x $(PY) || python3 -m venv $(VENV)
	$(PY) -m pip install -q pip==26.3
	$(PY) -m pip install -q --no-deps torch==2.13.0
	$(PY) -m pip install -q --require-hashes --no-deps -r $(LOCK)
	$(PY) -m pip install -q --no-deps --no-build-isolation -e .
	$(PY) -m pip check
	touch $(STAMP)

# `make lock` refreshes $(LOCK) from pyproject.toml (runtime + test + ray + robotics extras), keeping each
# pin that pyproject.toml still allows; `make lock UPGRADE=1` moves every package to its newest
# allowed release. uv comes from the package registry into tmp/. torch is resolved out (a
# never-true marker), and the CPU build's own requirements (TORCH_DEPS, its Requires-Dist) are
# locked in its place, so no CUDA package enters the lock.
UV_VERSION := 0.13.9
UV_VENV    := tmp/uv-$(UV_VERSION)
TORCH_DEPS := 'filelock' 'typing-extensions>=4.10.0' 'setuptools>=77.0.3' 'sympy>=1.13.3' \
              'networkx>=2.5.1' 'jinja2' 'fsspec>=0.8.5'
lock:
	test -x $(UV_VENV)/bin/uv || { python3 -m venv $(UV_VENV) && $(UV_VENV)/bin/pip install -q uv==$(UV_VERSION); }
	mkdir -p tmp/lock
	printf '%s\n' 'torch; sys_platform == "never"' > tmp/lock/no-torch.txt
	printf '%s\n' $(TORCH_DEPS) > tmp/lock/torch-2.13.0-requires.in
	$(UV_VENV)/bin/uv pip compile --no-config -q pyproject.toml tmp/lock/torch-2.13.0-requires.in \
	  --extra test --extra ray --extra robotics --override tmp/lock/no-torch.txt \
	  --python-version 3.11 --python-platform x86_64-manylinux_2_28 \
	  --generate-hashes --custom-compile-command 'make lock' $(if $(UPGRADE),--upgrade) -o $(LOCK)
	! grep -iE '^(torch|triton|nvidia-|cuda-)' $(LOCK)

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

# The whole suite twice: torch on one thread, then on two (tests/conftest.py reads DFA_TORCH_THREADS).
# Each run goes to its end, so that one failure hides no other; the target fails if either failed.
test: setup
	one=0; DFA_TORCH_THREADS=1 $(PY) -m pytest -q --durations=25 || one=$$?; \
	two=0; DFA_TORCH_THREADS=2 $(PY) -m pytest -q --durations=25 || two=$$?; \
	echo "make test: exit $$one with torch on one thread, $$two on two"; \
	[ $$one -eq 0 ] && [ $$two -eq 0 ]

bench: setup
	$(VENV)/bin/dfa bench

lint: setup
	$(PY) -m ruff check .
	$(PY) -m ruff format --check .
	$(PY) -m mypy --follow-imports=silent sim/core search

format: setup
	$(PY) -m ruff format .
	$(PY) -m ruff check --fix .
