# One target per CI step; `.ci/run` calls `make test`, the README's test command.
PY ?= python3
APT_PACKAGES := gcc-avr avr-libc qemu-system-misc arduino-core-avr chromium chromium-driver valgrind \
                gcc-arm-none-eabi libnewlib-arm-none-eabi qemu-system-arm

.PHONY: deps install test test-rust test-python lint stubs docs bench bench-instructions instructions-guard demo wheel wheel-check firmware-check

# Debian packages the tests need (the AVR firmware build, its QEMU run, the Arduino sketch
# built against the Arduino AVR core; the firmware library's Cortex-M3 build and QEMU run;
# the headless browser of the live page's tests; valgrind
# for the instruction counts). Skipped when everything is present already; needs root (as on
# CI) otherwise.
deps:
	@missing=""; for p in $(APT_PACKAGES); do dpkg -s $$p >/dev/null 2>&1 || missing="$$missing $$p"; done; \
	if [ -n "$$missing" ]; then \
	  echo "installing Debian packages:$$missing"; \
	  if [ "$$(id -u)" = 0 ]; then SUDO=""; else SUDO="sudo"; fi; \
	  $$SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -qq --no-install-recommends $$missing >/dev/null; \
	fi

# The package in editable mode with its test extras (builds the Rust core in release mode).
install:
	$(PY) -m pip install -q -e '.[test]'

test-rust:
	cargo test --no-default-features --quiet

test-python:
	$(PY) -m pytest -q

lint:
	$(PY) -m ruff check python tests benches docs
	$(PY) -m mypy python/triaxcal --ignore-missing-imports
	$(PY) -m mypy.stubtest triaxcal._core

# A wheel that installs without Rust: abi3 (CPython >= 3.9), manylinux2014 (glibc >= 2.17),
# cross-linked with zig (the `ziglang` package from PyPI), plus the sdist, into dist/.
wheel:
	$(PY) -m pip install -q 'maturin>=1.7,<2' 'ziglang>=0.13'
	rm -rf dist
	maturin build --release --zig --compatibility manylinux2014 --out dist
	maturin sdist --out dist

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
docs:
	$(PY) -m sphinx -b html -W --keep-going -j auto docs docs/_build/html

# Everything: the README's test command, and what CI runs. The site is built before pytest,
# whose tests/test_docs_site.py opens it in a browser.
test: deps install test-rust lint docs test-python firmware-check instructions-guard wheel-check

bench:
	$(PY) benches/bench_fit.py

# Instruction counts with valgrind (callgrind): per point per pass, per fit, per batch set.
bench-instructions:
	$(PY) benches/instructions.py

# The regression guard: a fit of 10 points, a fixed 1e5-point fit and a fixed batch may not grow by more than 10 %
# over benches/instructions.json (update it with `benches/instructions.py --update`).
instructions-guard:
	$(PY) benches/instructions.py --check

demo:
	triaxcal demo
