# eegt_blender: `make demo` runs the main job on a bundled tangled mesh, `make test` runs
# every test suite. Both create .venv (Python 3.11) on first use.
SHELL := /bin/bash
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed-stamp

# pytest on every core (pytest-xdist): each worker is its own process with its own Blender
# sandbox; XDIST= runs in one process.
XDIST ?= -n auto
E2E_ROOT := .e2e-root/rootfs

.PHONY: venv numpy2 test test-fast lint test-core test-blender test-bench test-compat e2e demo build bench bench-paper bench-batch clean

venv: $(STAMP)

$(STAMP): pyproject.toml
	@$(PYTHON) -c 'import sys; sys.exit(0 if sys.version_info[:2] == (3, 11) else "Python 3.11 is needed (Blender 4.2-5.0 run 3.11), found " + sys.version.split()[0])'
	@$(PYTHON) -m venv --help >/dev/null 2>&1 && $(PYTHON) -c 'import ensurepip' 2>/dev/null || \
	  { [ "$$(id -u)" = 0 ] && apt-get update -q && apt-get install -y -q python3-venv; }
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q --group dev
	@# gmsh (test and benchmark meshes) loads X11/OpenGL libraries a slim Debian lacks
	@$(PY) -c 'import gmsh' 2>/dev/null || { [ "$$(id -u)" = 0 ] && apt-get update -q && \
	  apt-get install -y -q libglu1-mesa libgl1 libxcursor1 libxft2 libxinerama1; }
	touch $(STAMP)

lint: $(STAMP)
	$(PY) -m ruff check .

# Lint and every test not marked slow or e2e: the check while working; `make test` runs all.
test-fast: lint
	$(PY) -m pytest -q $(XDIST) -m "not slow and not e2e" tests

test-core: $(STAMP)
	$(PY) -m pytest -q -m "not blender and not e2e" tests

test-blender: $(STAMP)
	$(PY) -m pytest -q -m blender tests

# The tests of the benchmark scripts alone (tests/bench, marked bench); test, test-fast and
# test-core run them with the rest.
test-bench: $(STAMP)
	$(PY) -m pytest -q -m bench tests/bench

# Pure zip + per-platform zips bundling pyopencl for CPython 3.11/3.13 (downloads into
# build/wheels), each checked with Blender's own validator.
build: $(STAMP)
	$(PY) scripts/build_extension.py --platforms

# The Blender tests against the bpy wheels of the 4.2 and 4.5 LTS series (separate venvs,
# made again when a half-finished install cannot import its packages); every series runs,
# and the target fails when one did.
COMPAT_BPY ?= 4.2.23 4.5.15
test-compat:
	@failed=""; for v in $(COMPAT_BPY); do \
	  d=build/compat/bpy-$$v; \
	  $$d/bin/python -c "import bpy, numpy, pytest" 2>/dev/null || { rm -rf $$d && \
	    $(PYTHON) -m venv $$d && $$d/bin/pip install -q "bpy==$$v" "numpy<2" pytest; } || \
	    { failed="$$failed $$v"; continue; }; \
	  echo "== bpy $$v"; $$d/bin/python -m pytest -q -p no:cacheprovider tests/blender || \
	    failed="$$failed $$v"; \
	done; [ -z "$$failed" ] || { echo "test-compat failed for bpy$$failed"; exit 1; }

# The e2e root (Debian packages: mostly download and unpack) is made while pytest runs.
test: lint numpy2
	@mkdir -p build; [ "$$(id -u)" != 0 ] || { bash tests/e2e/setup_root.sh $(E2E_ROOT) \
	  >build/e2e-root.log 2>&1 & }; \
	EEGT_NUMPY2_PYTHON=$(NUMPY2)/bin/python $(PY) -m pytest -q $(XDIST) -m "not e2e" tests; \
	rc=$$?; wait; exit $$rc
	$(MAKE) e2e

# A second interpreter with NumPy >= 2.3 (whose long sums are ordered differently from
# NumPy 1's): tests/core/test_reproducibility.py checks the core gives the same bits there.
NUMPY2 := build/numpy2
numpy2: $(NUMPY2)/.installed-stamp

$(NUMPY2)/.installed-stamp:
	rm -rf $(NUMPY2) && $(PYTHON) -m venv $(NUMPY2)
	$(NUMPY2)/bin/pip install -q "numpy>=2.3" pytest
	touch $@

# Build + install the extension into a sandboxed headless Blender (bpy), untangle a bundled
# tangled mesh with the operator, save out/demo.blend and out/demo_before_after.png.
demo: $(STAMP)
	$(PY) -m bench.demo --out out

# The scale table: generated tangled meshes of 100k, 1M and 4M triangles and 1M quads, NumPy
# and auto (time, quality, peak RSS, time per element) and docs/scale.png. Per-iteration
# tables of the engines: python -m bench.run.
bench: $(STAMP)
	$(PY) -m bench.scale --plot docs/scale.png --json build/scale.json

# The paper's Tables 1-3 side by side with our modes, Blender's Smooth Vertices and the peers;
# rewrites the README's results block and docs/results.md. Robustness: bench.robustness.
bench-paper: $(STAMP)
	$(PY) -m bench.paper_tables --readme

# Many files through the eegt command in the e2e root's Blender (root needed; ~40 min for
# 200 files on 2 cores): shell loop vs --jobs vs --dask, start-up and memory per worker.
bench-batch:
	bash bench/batch_bench.sh

# Real Blender 4.3 in a Debian 13 chroot (root needed; cached in .e2e-root/): tests/e2e/.
e2e:
	bash tests/e2e/run_e2e.sh

clean:
	rm -rf $(VENV) dist out .pytest_cache .ruff_cache
