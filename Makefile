# The two commands: `make book` builds the whole book from freshly executed notebooks,
# `make test` runs the test suite. Both create .venv from environment.lock when missing.
SHELL := /bin/bash
.SHELLFLAGS := -euo pipefail -c
PYTHON ?= python3.11
VENV := .venv
BIN := $(VENV)/bin
MATHJAX := book/_mathjax/node_modules/mathjax/es5/tex-chtml.js

.PHONY: book book-quick test venv chromium lock clean

venv: $(BIN)/railpaper $(MATHJAX)

$(BIN)/railpaper: environment.lock pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --require-hashes --no-deps --no-compile -r environment.lock
	$(BIN)/python -m compileall -q -j 0 $(VENV)/lib > /dev/null
	$(BIN)/python -m pip install --quiet --no-deps --no-build-isolation -e .
	touch $(BIN)/railpaper

# MathJax 3 for the offline book, pinned by book/_mathjax/package-lock.json. It lives outside
# _static: Jupyter Book 1 adds every .js file under _static to every page as a <script>.
$(MATHJAX): book/_mathjax/package.json book/_mathjax/package-lock.json
	cd book/_mathjax && npm ci --silent --no-audit --no-fund
	touch $(MATHJAX)

book: venv
	$(BIN)/railpaper build

book-quick: venv
	$(BIN)/railpaper build --quick

# The rendering test (tests/pipeline/test_book.py) opens the built pages in headless Chromium: Debian's
# package is installed when missing and we are root (or have sudo); otherwise one line says how.
chromium:
	@if command -v chromium >/dev/null 2>&1 || command -v chromium-browser >/dev/null 2>&1; then :; \
	elif [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
	  echo "make: installing Debian chromium for the rendering test"; \
	  apt-get update -q >/dev/null && DEBIAN_FRONTEND=noninteractive apt-get install -y -q chromium >/dev/null; \
	elif command -v sudo >/dev/null 2>&1 && sudo -n true 2>/dev/null && command -v apt-get >/dev/null 2>&1; then \
	  echo "make: installing Debian chromium for the rendering test"; \
	  sudo apt-get update -q >/dev/null && sudo DEBIAN_FRONTEND=noninteractive apt-get install -y -q chromium >/dev/null; \
	else echo "make: the rendering test needs Chromium: run 'sudo apt-get install chromium' (Debian/Ubuntu), then 'make test' again" >&2; exit 1; fi

# The engine's numba kernels compiled into numba's on-disk cache once, before the test workers and
# the quick book's chapter processes start together and would each compile them (railpaper
# compile: one record of every study on two processes); again only when the package changes.
KERNELS := $(VENV)/.numba-kernels
$(KERNELS): $(BIN)/railpaper $(shell find railpaper -name '*.py')
	$(BIN)/railpaper compile --jobs 2
	touch $(KERNELS)

test: venv chromium $(KERNELS)
	$(BIN)/python -m pytest -q -n 2 --dist loadfile --no-loadscope-reorder

# Regenerate the hashed lock from pyproject.toml (needs uv: `pip install uv`).
lock:
	uv pip compile pyproject.toml --extra test --generate-hashes \
	  --python-version 3.11 --python-platform x86_64-unknown-linux-gnu -o environment.lock

clean:
	rm -rf book/_build
