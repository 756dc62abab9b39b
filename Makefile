# The two commands: `make book` builds the whole book from freshly executed notebooks,
# `make test` runs the test suite. Both create .venv from environment.lock when missing.
SHELL := /bin/bash
.SHELLFLAGS := -euo pipefail -c
PYTHON ?= python3.11
VENV := .venv
BIN := $(VENV)/bin
MATHJAX := book/_static/mathjax/node_modules/mathjax/es5/tex-chtml.js

.PHONY: book book-quick test venv lock clean

venv: $(BIN)/railpaper $(MATHJAX)

$(BIN)/railpaper: environment.lock pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --require-hashes --no-deps -r environment.lock
	$(BIN)/python -m pip install --quiet --no-deps --no-build-isolation -e .
	touch $(BIN)/railpaper

# MathJax 3 for the offline book, pinned by book/_static/mathjax/package-lock.json.
$(MATHJAX): book/_static/mathjax/package.json book/_static/mathjax/package-lock.json
	cd book/_static/mathjax && npm ci --silent --no-audit --no-fund
	touch $(MATHJAX)

book: venv
	$(BIN)/railpaper build

book-quick: venv
	$(BIN)/railpaper build --quick

test: venv
	$(BIN)/python -m pytest -q

# Regenerate the hashed lock from pyproject.toml (needs uv: `pip install uv`).
lock:
	uv pip compile pyproject.toml --extra test --generate-hashes \
	  --python-version 3.11 --python-platform x86_64-unknown-linux-gnu -o environment.lock

clean:
	rm -rf book/_build
