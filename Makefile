# optrack: the README's two commands are `make run` and `make test`.
# Both install what is missing (Debian packages, .venv, the project), then run.

PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.optrack-installed
NORFAIR := 2.3.0
XVFB   := xvfb-run -a -s "-screen 0 1280x1024x24"

.PHONY: setup system-deps run test test-2d test-gl lint bench clean wheel package test-package

setup: system-deps $(STAMP)

system-deps:
	@bash packaging/install-system-deps.sh

# norfair, the tracking bench's peer: its metadata pins numpy < 2 (it runs on 2.x), so it
# goes in without its pins; its dependencies (filterpy, rich, scipy) are in pyproject.
$(STAMP): pyproject.toml Makefile
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -e '.[dev]'
	$(BIN)/python -m pip install -q --no-deps norfair==$(NORFAIR)
	@touch $(STAMP)

run: setup
	$(BIN)/optrack gui

lint: setup
	$(BIN)/ruff check optrack app tests

# 2D widgets and everything without a display: offscreen Qt.
test-2d: setup
	QT_QPA_PLATFORM=offscreen $(BIN)/python -m pytest -m "not opengl and not slow"

# OpenGL (3D) widgets: a real X server (Xvfb) and Qt's xcb platform.
test-gl: setup
	QT_QPA_PLATFORM=xcb $(XVFB) $(BIN)/python -m pytest -m opengl

test: lint test-2d test-gl

# The wheel (dist/optrack-<version>-py3-none-any.whl) and the Debian package
# (dist/optrack_<version>_amd64.deb: /opt/optrack, /usr/bin/optrack, systemd units).
wheel: setup
	rm -f dist/optrack-*.whl
	$(BIN)/python -m pip wheel -q --no-deps -w dist .
	rm -rf build

package: wheel
	bash packaging/build-deb.sh

# Builds both, installs the wheel in a fresh venv and the .deb on this machine (as root),
# runs and removes them (docs/deploy.md, Tests). .ci/run runs it after make test.
test-package: setup
	QT_QPA_PLATFORM=offscreen $(BIN)/python -m pytest -m slow tests/packaging

BENCH ?= e2e
bench: setup
	$(BIN)/optrack bench $(BENCH) --json

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache .ruff_cache
