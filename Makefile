# robotadapt: every target sets up its own .venv with the machine's python3.
PY      ?= python3
VENV    := .venv
BIN     := $(VENV)/bin
PIP     := $(BIN)/python -m pip
STAMP   := $(VENV)/.stamp

.PHONY: demo test test-all bench docs clean system-packages

# SYSTEM_PACKAGES=0: install nothing outside .venv (the browser and video tests then skip, each saying why)
SYSTEM_PACKAGES ?= 1

$(BIN)/python:
	$(PY) -m venv $(VENV)
	$(PIP) install --quiet --upgrade pip

$(VENV)/.core: $(BIN)/python pyproject.toml   # every extra the README and the guides use ([all]), so none asks later
	$(PIP) install --quiet -e ".[all]"
	touch $@

$(VENV)/.dev: $(BIN)/python pyproject.toml
	$(PIP) install --quiet -e ".[dev,all]"
	touch $@

demo: $(VENV)/.core                ## set up and run the flagship example (Example 6.3.1) into results/
	$(BIN)/robotadapt run example-6.3.1 --out results/example-6.3.1

test: $(VENV)/.dev system-packages ## set up and run the fast test suite
	$(BIN)/ruff check src tests benchmarks docs
	$(BIN)/mypy
	$(BIN)/python -m pytest -q -n 2 -m "not slow"

system-packages:                   ## the two system packages some tests use, with apt-get, where missing (SYSTEM_PACKAGES=0 skips)
	@if [ "$(SYSTEM_PACKAGES)" = 0 ]; then echo "system packages: skipped (SYSTEM_PACKAGES=0); the browser and video tests skip"; \
	else \
	  command -v chromium >/dev/null 2>&1 || { echo "system packages: apt-get install chromium (headless browser for the docs' \
	and report's tests; skip with SYSTEM_PACKAGES=0)"; (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install \
	  -y -qq chromium >/dev/null) || echo "chromium not installable here: the browser tests skip"; }; \
	  ldconfig -p 2>/dev/null | grep -q libOSMesa || { echo "system packages: apt-get install libosmesa6 (off-screen OpenGL for \
	--video; skip with SYSTEM_PACKAGES=0)"; (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq \
	  libosmesa6 >/dev/null) || echo "libosmesa6 not installable here: --video fails, its test skips"; }; \
	fi

test-all: $(VENV)/.dev             ## every test, the slow studies included
	$(BIN)/python -m pytest -q -n 2

bench: $(VENV)/.dev                ## speed studies, ratios against a naive baseline measured in the same run
	@for f in benchmarks/bench_*.py; do echo "== $$f"; $(BIN)/python $$f || exit 1; done

docs: $(VENV)/.dev                 ## build the documentation site into site/ (warnings are errors)
	$(BIN)/mkdocs build --strict

clean:
	rm -rf $(VENV) results build src/*.egg-info
