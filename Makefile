# One target per CI step; `.ci/run` calls `make test`, the README's test command.

# The Python of every step: PY=... when given; else the active virtual environment's (or conda
# environment's); else that of .venv in the checkout, created by `make install` (a system Python
# such as Debian's refuses `pip install` outside a virtual environment: PEP 668).
VENV := .venv
VENV_PYTHON ?= python3
ifeq ($(origin PY),undefined)
  ifneq ($(VIRTUAL_ENV),)
    PY := $(VIRTUAL_ENV)/bin/python
  else ifneq ($(CONDA_PREFIX),)
    PY := $(CONDA_PREFIX)/bin/python
  else
    PY := $(VENV)/bin/python
  endif
endif
# .venv is made only when PY is its Python; then its tools come first on PATH, as in an
# activated environment (maturin finds the ziglang package's zig through it)
PY_DEP := $(filter $(VENV)/bin/python,$(PY))
ifneq ($(PY_DEP),)
  export PATH := $(abspath $(VENV))/bin:$(PATH)
endif

APT_PACKAGES := gcc python3-venv gcc-avr avr-libc qemu-system-misc arduino-core-avr chromium \
                chromium-driver valgrind gcc-arm-none-eabi libnewlib-arm-none-eabi qemu-system-arm

.PHONY: deps install data test test-rust test-python lint stubs docs bench bench-speed bench-instructions instructions-guard screenshot demo wheel wheel-check firmware-check

# Debian packages the tests need (a C compiler and venv for the build; the AVR firmware build,
# its QEMU run, the Arduino sketch built against the Arduino AVR core; the firmware library's
# Cortex-M3 build and QEMU run; the headless browser of the live page's tests; valgrind
# for the instruction counts). Skipped when everything is present already; needs root (as on
# CI) otherwise.
deps:
	@missing=""; for p in $(APT_PACKAGES); do dpkg -s $$p >/dev/null 2>&1 || missing="$$missing $$p"; done; \
	if [ -n "$$missing" ]; then \
	  echo "installing Debian packages:$$missing"; \
	  if [ "$$(id -u)" = 0 ]; then SUDO=""; else SUDO="sudo"; fi; \
	  $$SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -qq --no-install-recommends $$missing >/dev/null; \
	fi

$(VENV)/bin/python:
	@$(VENV_PYTHON) -m venv $(VENV) || { rm -rf $(VENV); \
	  echo "could not create $(VENV) with $(VENV_PYTHON): on Debian or Ubuntu run 'make deps'" \
	       "(or apt-get install python3-venv) first, or give PY=/path/to/python" >&2; exit 1; }
	$@ -m pip install -q --upgrade pip

# The package in editable mode with its test extras (builds the Rust core in release mode, with
# the benchmark hooks that benches/ and the instruction guard call; `make wheel` leaves them out).
install: $(PY_DEP)
	MATURIN_PEP517_ARGS="--features bench-hooks" $(PY) -m pip install -q -e '.[test]'

# The real recordings the tests read (tests/data/registry.txt): checked, and downloaded into the
# cache when neither kept in tests/data nor in a local copy (TRIAXCAL_REALDATA, ../shared/realdata).
data: $(PY_DEP)
	@$(PY) -c "import pooch" 2>/dev/null || $(PY) -m pip install -q 'pooch>=1.6'
	$(PY) tests/fetch_data.py

test-rust:
	cargo test --no-default-features --quiet

test-python:
	$(PY) -m pytest -q

lint:
	$(PY) -m ruff check python tests benches docs
	$(PY) -m mypy python/triaxcal --ignore-missing-imports
	$(PY) -m mypy.stubtest triaxcal._core --allowlist .stubtest-allowlist --ignore-unused-allowlist

# A wheel that installs without Rust: abi3 (CPython >= 3.9), manylinux2014 (glibc >= 2.17),
# cross-linked with zig (the `ziglang` package from PyPI), plus the sdist, into dist/.
wheel:
	$(PY) -m pip install -q 'maturin>=1.7,<2' 'ziglang>=0.13'
	rm -rf dist
	$(PY) -m maturin build --release --zig --compatibility manylinux2014 --out dist
	$(PY) -m maturin sdist --out dist

# Install dist/'s wheel into a fresh venv with no Rust on PATH; run the quick start and the demo.
wheel-check: wheel
	PYTHON=$(PY) bash scripts/check_wheel.sh dist

# The firmware's C library against the core's test vectors: host, ATmega328P and Cortex-M3
# (QEMU).
firmware-check:
	$(MAKE) -C firmware check

# The documentation site into docs/_build/html (open docs/_build/html/index.html; it works
# offline): Sphinx with warnings as errors, the gallery's examples run, the API and command-line
# reference generated from the package. Needs the docs extra (part of the test extra).
docs: $(PY_DEP)
	$(PY) -m sphinx -b html -W --keep-going -j auto docs docs/_build/html

# Everything: the README's test command, and what CI runs. The site is built before pytest,
# whose tests/test_docs_site.py opens it in a browser.
test: deps install data test-rust lint docs test-python firmware-check instructions-guard wheel-check

bench:
	$(PY) benches/bench_fit.py

# Every speed target against its strongest baseline; rewrites docs/benchmarks/results.md.
bench-speed:
	$(PY) benches/bench_speed.py --markdown docs/benchmarks/results.md

# Instruction counts with valgrind (callgrind): per point per pass, per fit, per batch set.
bench-instructions:
	$(PY) benches/instructions.py

# The regression guard: a fit of 10 points, a fixed 1e5-point fit, a fixed batch, the Allan deviation and the two
# log readers may not grow by more than 10 % over benches/instructions.json (update it with
# `benches/instructions.py --update`).
instructions-guard:
	$(PY) benches/instructions.py --check

# Retakes the README's screenshot of the live page (docs/live.png) in headless Chromium.
screenshot:
	TRIAXCAL_UPDATE_SCREENSHOT=1 $(PY) -m pytest -q tests/test_live_browser.py

demo:
	$(PY) -c "import sys; from triaxcal.cli import main; sys.exit(main(['demo']))"
