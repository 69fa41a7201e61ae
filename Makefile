# SceneFit developer commands. A newcomer needs two: `make demo` and `make test`.
SHELL := /bin/bash
.DEFAULT_GOAL := help

VENV     := .venv
PY       := $(VENV)/bin/python
STAMP    := $(VENV)/.scenefit-setup
PLATFORM ?= linux-x64

# Mitsuba's llvm variant loads this library (found lazily, after `setup` may have installed it).
export DRJIT_LIBLLVM_PATH ?= $(shell tools/find_llvm.sh 2>/dev/null)

.PHONY: help setup test test-quick demo docs bench corpus prior extension extension-nowheels check-extension validate clean

help:
	@echo "make demo       set up on first use, run SceneFit on the bundled example -> out/demo/"
	@echo "make test       set up on first use, run the tests (all of them: what CI runs)"
	@echo "make test-quick the tests without those marked slow (multi-process, worker environments)"
	@echo "make docs       the docs site into build/docs/ (warnings are errors; the tests build it too)"
	@echo "make bench      speed and accuracy table (benchmarks/run.py)"
	@echo "make gpu-check  on a CUDA machine: SD2-sized random models, each preset's adapt iterations, benchmarks/results/gpu.md"
	@echo "make prior      the known-answer diffusion prior (a test instrument, never for artists' work) into"
	@echo "                devtools/prior/ (PRIOR=DIR: DIR/base, DIR/inpaint); nothing to do when it is up to date"
	@echo "make corpus     every real asset in ../shared/corpus through convert -> bake -> glTF validator"
	@echo "                (benchmarks/results/corpus.md; installs npm's gltf-validator into .venv/node), and through"
	@echo "                the Blender extension: Import Asset -> Run All -> Bake Asset (corpus_blender.md)"
	@echo "make extension PLATFORM=linux-x64|linux-arm64|windows-x64|macos-arm64|macos-x64"
	@echo "                download runtime wheels, list them in the manifest, build dist/*.zip"
	@echo "make extension-nowheels   pure-Python zip without wheels (what the install test uses)"
	@echo "make check-extension PLATFORM=... [BPY=4.2.0]  build the zip, install it into a bare bpy venv"
	@echo "                (this checkout's Blender, or BPY's), run the stages there in an artist's scene"
	@echo "                (slow; not part of make test)"

setup: $(STAMP)

# Re-run only when the pins or the packaging change; tools/setup.sh is itself idempotent.
$(STAMP): requirements.txt requirements-ray.txt pyproject.toml tools/setup.sh tools/find_llvm.sh
	tools/setup.sh
	@touch $@

# Two workers, one per core (pytest-xdist); each test file stays in one worker, in its order, so a
# module's shared Blender session or built assets are made once (measured against one test per worker:
# 420 s against 454 s; one worker: 534 s).
TEST_WORKERS ?= 2
test: setup
	$(PY) -m pytest -q -n $(TEST_WORKERS) --dist loadfile --durations=25 tests

test-quick: setup
	$(PY) -m pytest -q -n $(TEST_WORKERS) --dist loadfile -m "not slow" tests

demo: setup
	$(VENV)/bin/scenefit demo --out out/demo

docs: setup
	$(PY) -m sphinx -W -n --keep-going -b html docs build/docs
	@echo "open build/docs/index.html"

bench: setup
	$(PY) benchmarks/run.py

# The known-answer prior (devtools/train_prior.py): ~10 min on two cores; skipped when the weights in
# PRIOR were made by the current sources (their hash is stamped beside them).
PRIOR ?= devtools/prior
prior: setup
	$(PY) -m scenefit.devtools.train_prior --out $(PRIOR)

corpus: setup
	$(PY) benchmarks/corpus.py
	$(PY) benchmarks/corpus_blender.py

# On a machine with a CUDA GPU: SD2-sized random models, each preset's adapt iterations, gpu.md (3 min on an H200).
gpu-check: setup
	$(PY) benchmarks/gpu_check.py

validate: setup
	$(PY) tools/build_extension.py validate

extension: setup
	$(PY) tools/build_extension.py wheels --platform $(PLATFORM)
	$(PY) tools/build_extension.py build --platform $(PLATFORM)

check-extension: setup
	$(PY) tools/check_extension.py --platform $(PLATFORM) $(if $(BPY),--bpy $(BPY))

extension-nowheels: setup
	$(PY) tools/build_extension.py nowheels

clean:
	rm -rf dist build out .pytest_cache
