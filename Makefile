# Every target sets itself up: system packages, a virtual environment, arapp.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
ARAPP  := $(VENV)/bin/arapp
STAMP  := $(VENV)/.arapp-installed
# The real OctoPrint server for the REST-link tests lives in its own environment (see the requirements file).
OCTO   := .venv-octoprint
OCTO_STAMP := $(OCTO)/.installed
# The real Moonraker and the Klipper host behind it, for the Moonraker-link tests: each in its own environment.
MOON   := .venv-moonraker
MOON_STAMP := $(MOON)/.installed
KLIPPY := .venv-klippy
KLIPPY_STAMP := $(KLIPPY)/.installed
# The real PrusaLink, for the PrusaLink-link tests, in its own environment.
PRUSALINK := .venv-prusalink
PRUSALINK_STAMP := $(PRUSALINK)/.installed
SERVER_STAMPS := $(OCTO_STAMP) $(MOON_STAMP) $(KLIPPY_STAMP) $(PRUSALINK_STAMP)

# `make test` runs the suite in TEST_WORKERS processes (pytest-xdist): three on CI's 2-core machine, as a third
# of the suite's time waits on printer servers, serial links and GUI event loops rather than computing (measured
# on this 2-core machine: 4 min 32 s with 2 workers, 3 min 28 s with 3, 3 min 13 s with 4; with 6 the real
# PrusaLink stopped answering in time, and with 4 beside other load a serial-link test with 2 s windows once
# stopped on a resend it took for garbled: 3 leaves the timing tests more room). --dist loadfile keeps each test file on one worker, so its module
# fixtures are built once, and the files of one real printer server together, so it starts once
# (tests/conftest.py SERVER_GROUPS, its scheduler); the groups go out longest first (FILE_SECONDS there;
# --no-loadscope-reorder keeps that order). 0: one process.
TEST_WORKERS ?= 3
# processes rendering the recordings cache at once (computing only: one per core)
RENDER_JOBS ?= $(shell nproc 2>/dev/null || echo 2)

export PYOPENGL_PLATFORM ?= egl
export QT_QPA_PLATFORM ?= offscreen
export MPLBACKEND ?= Agg

.PHONY: setup demo test bench recordings clean

setup: $(STAMP) $(SERVER_STAMPS) recordings

$(STAMP): pyproject.toml constraints.txt requirements-peers.txt scripts/system-deps.sh
	./scripts/system-deps.sh prusa-slicer
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -c constraints.txt -e '.[test,scan]'
	$(PY) -m pip install -q -c constraints.txt -r requirements-peers.txt
	$(PY) -m pip install -q --no-deps OctoPrint==1.11.8 Printrun==2.2.0
	# pyrender pins PyOpenGL 3.1.0, which cannot use EGL on current Mesa.
	$(PY) -m pip install -q 'PyOpenGL==3.1.10' 2>&1 | grep -v "dependency conflicts\|pyrender 0.1.45 requires\|resolver does not" || true
	touch $(STAMP)

$(OCTO_STAMP): requirements-octoprint-server.txt
	test -x $(OCTO)/bin/python || $(PYTHON) -m venv $(OCTO)
	$(OCTO)/bin/python -m pip install -q --upgrade pip
	$(OCTO)/bin/python -m pip install -q -r requirements-octoprint-server.txt
	touch $(OCTO_STAMP)

$(MOON_STAMP): requirements-moonraker-server.txt
	test -x $(MOON)/bin/python || $(PYTHON) -m venv $(MOON)
	$(MOON)/bin/python -m pip install -q --upgrade pip
	$(MOON)/bin/python -m pip install -q -r requirements-moonraker-server.txt
	touch $(MOON_STAMP)

# Klippy's build compiles its C helper and hub-ctrl (which includes usb.h: libusb-dev).
$(KLIPPY_STAMP): requirements-klippy-server.txt scripts/system-deps.sh
	./scripts/system-deps.sh gcc libusb-dev
	test -x $(KLIPPY)/bin/python || $(PYTHON) -m venv $(KLIPPY)
	$(KLIPPY)/bin/python -m pip install -q --upgrade pip
	$(KLIPPY)/bin/python -m pip install -q -r requirements-klippy-server.txt
	touch $(KLIPPY_STAMP)

# python-prctl compiles against libcap; PrusaLink loads libturbojpeg at import and libmagic for uploads.
$(PRUSALINK_STAMP): requirements-prusalink-server.txt scripts/system-deps.sh
	./scripts/system-deps.sh gcc libcap-dev libturbojpeg0 libmagic1
	test -x $(PRUSALINK)/bin/python || $(PYTHON) -m venv $(PRUSALINK)
	$(PRUSALINK)/bin/python -m pip install -q --upgrade pip
	$(PRUSALINK)/bin/python -m pip install -q -r requirements-prusalink-server.txt
	touch $(PRUSALINK_STAMP)

demo: $(STAMP)
	$(ARAPP) demo --out out/demo

# (bytecode written: without it every worker and every program a test starts compiles arapp again, and pytest
# rewrites every test file's asserts again, seconds of CPU each; an environment may turn it off)
test: export PYTHONDONTWRITEBYTECODE =
test: $(STAMP) $(SERVER_STAMPS) recordings
	$(VENV)/bin/lint-imports --no-cache && $(PY) -m pytest -q -p no:cacheprovider -n $(TEST_WORKERS) --dist loadfile --no-loadscope-reorder tests

# Every synthetic preset's recording the tests and benchmarks read (the bundled ones in recordings/, the rest
# rendered once into the recordings cache, .cache/recordings/, see recordings/README.md) and the tests' own scenes
# (tests/scene_book.py); a few seconds when they are there. Part of the set-up; tests and benchmarks would
# render a missing one on first use.
recordings: $(STAMP)
	$(ARAPP) synth all --cached --jobs $(RENDER_JOBS) >/dev/null
	$(PY) tests/scene_book.py --jobs $(RENDER_JOBS)

bench: $(STAMP)
	$(PY) benchmarks/run_all.py --out BENCHMARKS.md $(if $(ONLY),--only $(ONLY) --merge)

clean:
	rm -rf $(VENV) $(OCTO) $(MOON) $(KLIPPY) $(PRUSALINK) .prusalink-test out .cache/recordings
