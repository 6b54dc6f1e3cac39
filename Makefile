# Two commands from nothing:  `make demo`  and  `make test`.
# `make setup` (run by both) is idempotent: apt packages, .venv, editable install.
# `make docs` builds the manual (Sphinx + MyST + furo, from Debian): docs/_build/html/index.html.

SHELL        := /bin/bash
VENV         := .venv
PY           := $(VENV)/bin/python
SYSTEM_PY    := /usr/bin/python3
APT_PACKAGES := python3-dolfinx python3-numba python3-mpi4py python3-petsc4py \
                python3-gmsh python3-meshio python3-h5py python3-matplotlib \
                python3-scipy python3-pytest python3-venv python3-pip openmpi-bin make \
                python3-sphinx python3-myst-parser furo
PIP_EXTRAS   := pydantic>=2,<3 tomli-w>=1.0 ruff>=0.17,<0.18
STAMP        := $(VENV)/.setup-done
# OpenMPI refuses to run as root and to oversubscribe 2 cores unless told; these
# are also appended to .venv/bin/activate, so `mpirun -n 4 cosim run CASE` works.
export OMPI_ALLOW_RUN_AS_ROOT := 1
export OMPI_ALLOW_RUN_AS_ROOT_CONFIRM := 1
export OMPI_MCA_rmaps_base_oversubscribe := 1
MPIRUN       := mpirun --oversubscribe --bind-to none  # unbound: Numba threads may use both cores
DEMO_CASE    ?= runs/footing_small.toml

.PHONY: setup demo demo-plate demo-shear lab-series docs docs-reference test test-slow bench bench-peers bench-mpi \
        bench-coupled clean

setup: apt-packages $(STAMP)

apt-packages:
	@missing=""; for p in $(APT_PACKAGES); do \
	  dpkg-query -W -f='$${Status}' $$p 2>/dev/null | grep -q "ok installed" || missing="$$missing $$p"; \
	done; \
	if [ -n "$$missing" ]; then \
	  echo "setup: installing Debian packages:$$missing"; \
	  SUDO=""; [ "$$(id -u)" = 0 ] || SUDO=sudo; \
	  $$SUDO apt-get update -qq && \
	  DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -qq --no-install-recommends $$missing; \
	fi

$(STAMP): pyproject.toml Makefile
	@test -x $(PY) || $(SYSTEM_PY) -m venv --system-site-packages $(VENV)
	$(PY) -m pip install -q --disable-pip-version-check $(foreach p,$(PIP_EXTRAS),'$(p)')
	$(PY) -m pip install -q --disable-pip-version-check --no-deps --no-build-isolation -e .
	@grep -q OMPI_ALLOW_RUN_AS_ROOT $(VENV)/bin/activate || printf '%s\n' \
	  'export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1' \
	  >> $(VENV)/bin/activate
	$(PY) -c "import numpy, numba, mpi4py, dolfinx; assert numpy.__file__.startswith('/usr/lib/python3/'), 'a second numpy shadows Debian numpy: ' + numpy.__file__"
	@touch $(STAMP)

# the small footing demo: a strip footing on a DEM zone embedded in an FE soil block, then its all-DEM
# reference from the same case, and their comparison (runs/out/footing_small/comparison.png)
demo: setup
	$(VENV)/bin/cosim run $(DEMO_CASE)
	$(VENV)/bin/cosim run $(DEMO_CASE) --set footing.model=dem

demo-plate: setup
	$(VENV)/bin/cosim run runs/coupled_footing_on_sand.toml

demo-shear: setup
	$(VENV)/bin/cosim run runs/direct_shear_small.toml

lab-series: setup
	$(VENV)/bin/cosim series runs/direct_shear_small.toml runs/direct_shear_small_loose.toml --out runs/out/direct_shear_series_small

# the manual: docs/_build/html/index.html (any Sphinx warning is an error). It builds the
# committed docs/reference/case-file.md as it is; `make docs-reference` regenerates that
# page from the schema in cosim/case.py (tests/docs checks it is up to date).
docs: setup
	$(PY) -m sphinx -W --keep-going -b html docs docs/_build/html

docs-reference: setup
	$(PY) -m cosim.schema_doc docs/reference/case-file.md

test: setup docs
	$(VENV)/bin/ruff check .
	$(PY) -m pytest -m "not slow and not mpi" -q --color=no
	timeout 1200 $(MPIRUN) -n 2 $(PY) -m pytest -m "mpi and not slow" -q --color=no -p no:cacheprovider
	timeout 600 $(MPIRUN) -n 3 $(PY) -m pytest -m "mpi and not slow" -q --color=no -p no:cacheprovider \
	  tests/dem/test_distributed.py

test-slow: setup
	$(PY) -m pytest -m slow -q --color=no

bench: setup
	$(PY) benchmarks/dem_throughput.py
	$(PY) benchmarks/fe_throughput.py

# DEM peers side by side (W1 bed; rods against fix multisphere): installs the Debian liggghts and yade packages
# here only (never in setup/test).
bench-peers: setup
	@missing=""; for p in liggghts yade; do \
	  dpkg-query -W -f='$${Status}' $$p 2>/dev/null | grep -q "ok installed" || missing="$$missing $$p"; \
	done; \
	if [ -n "$$missing" ]; then \
	  echo "bench-peers: installing Debian packages:$$missing"; \
	  SUDO=""; [ "$$(id -u)" = 0 ] || SUDO=sudo; \
	  $$SUDO apt-get update -qq && \
	  DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -qq --no-install-recommends $$missing; \
	fi
	$(PY) benchmarks/compare_peers.py
	$(PY) benchmarks/clump_scaling.py --liggghts

# coupled FE step against the DEM window and the FE step alone, the DEM step's slowdown
# when other bytes stream through the cache between its steps, and a 2-rank coupled step
# split into kernels and the rest (README "Coupling overhead")
bench-coupled: setup
	$(PY) benchmarks/coupled_overhead.py
	$(PY) benchmarks/cache_contention.py
	$(PY) benchmarks/coupled_step_split.py

# DEM over MPI ranks (80k and 320k beds, 1/2 ranks, 1/2 threads; LIGGGHTS beside it when
# `make bench-peers` has installed it): README "DEM under MPI".
bench-mpi: setup
	$(PY) benchmarks/dem_scaling.py

clean:
	rm -rf $(VENV) runs/out .pytest_cache docs/_build
