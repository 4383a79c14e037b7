# simbake's front door. Every target installs what it needs, from a fresh Debian machine:
# missing system packages (apt-get, with sudo when not root), a virtual environment in
# .venv, and the package itself (built by scikit-build-core, incrementally, in build/py).
#
#   make demo    bake the shipped default scene and print where the USD went
#   make test    C++ tests (ctest) and Python tests (pytest)
#   make bench   run-time-versus-error sweeps, written into benchmarks/results
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
BUILD := build/py
export CMAKE_BUILD_PARALLEL_LEVEL ?= 2

# the core's build; then Mesa's CPU OpenGL through EGL for `simbake preview`
SYSTEM_PACKAGES := g++ make libopenvdb-dev libeigen3-dev libtbb-dev libboost-iostreams-dev libgtest-dev \
  libegl1 libegl-mesa0 libgl1 libgl1-mesa-dri
BUILD_REQUIRES := "scikit-build-core>=0.10" "pybind11>=2.12" "cmake>=3.18" ninja
SOURCES := $(shell find core bindings tests/cpp -name '*.cpp' -o -name '*.h') CMakeLists.txt pyproject.toml

.PHONY: demo test bench install system clean

demo: install
	$(VENV)/bin/simbake demo

# the Python tests on every CPU (pytest-xdist; the longest, a shipped cloth scene baked and
# checked at every frame, takes a few minutes alone)
test: install
	$(VENV)/bin/ctest --test-dir $(BUILD) --output-on-failure --timeout 300 -j2
	$(PY) -m pytest -n auto --dist worksteal --durations=10

bench: install
	$(PY) -m pip install -q "matplotlib>=3.7"
	$(PY) benchmarks/run_all.py

install: $(VENV)/.installed

system: build/.system-packages

# System packages: installed only when missing (dpkg -s is the check), checked again when
# this list changes
build/.system-packages: Makefile
	@missing=""; for p in $(SYSTEM_PACKAGES); do dpkg -s $$p >/dev/null 2>&1 || missing="$$missing $$p"; done; \
	if [ -n "$$missing" ]; then \
	  sudo=""; [ "$$(id -u)" -eq 0 ] || sudo=sudo; \
	  echo "installing system packages:$$missing"; \
	  $$sudo apt-get update -qq && DEBIAN_FRONTEND=noninteractive $$sudo apt-get install -y -qq $$missing; \
	fi
	@mkdir -p build && touch $@

$(VENV)/.build-requires: | build/.system-packages
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q $(BUILD_REQUIRES)
	touch $@

# The package, editable: Python changes need no reinstall; C++ changes rebuild incrementally.
# The checkout's root goes on the environment's path (a .pth file, as an editable install of a
# flat project writes), so that benchmark scripts in one folder import another folder's shared
# modules as the package `benchmarks` (benchmarks/__init__.py)
$(VENV)/.installed: $(VENV)/.build-requires $(SOURCES)
	$(PY) -m pip install -q --no-build-isolation -e '.[test,preview,wedge]' \
	  -Cbuild-dir=$(BUILD) -Ccmake.define.SIMBAKE_BUILD_TESTS=ON
	$(PY) -c 'import pathlib, sysconfig; pathlib.Path(sysconfig.get_path("purelib"), "simbake-checkout.pth").write_text("$(CURDIR)\n")'
	$(PY) -m compileall -q -j 0 pipeline/simbake  # (bytecode where PYTHONDONTWRITEBYTECODE is set: 0.1 s of each start)
	touch $@

clean:
	rm -rf build $(VENV)
