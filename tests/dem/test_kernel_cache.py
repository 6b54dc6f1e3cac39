"""Numba's on-disk cache never runs stale code (numba_support.kernel_cache): a cached kernel
that calls a kernel of another module is recompiled when that other module changes.

The probe counts the facet candidates of one sphere above a triangle. Its kernel
``neighbors._count_or_fill_facets`` calls ``walls.point_triangle_distance2``; the test
edits only ``walls.py`` (in a copy of the package), which Numba's own file stamp of
``neighbors.py`` would not notice."""
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import de_domain

PROBE = """
import numpy as np
import de_domain
from de_domain.neighbors import _count_or_fill_facets, build_cell_grid, build_facet_list

assert de_domain.__file__.startswith({root!r}), de_domain.__file__
pos = np.array([[1e-3, 1e-3, 1.5e-3]])
radius = np.array([1e-3])
vertices = np.array([[0.0, 0.0, 0.0], [4e-3, 0.0, 0.0], [0.0, 4e-3, 0.0]])
triangles = np.array([[0, 1, 2]])
grid = build_cell_grid(pos, 1, 4e-3, 1000)
f_start, f_tri = build_facet_list(pos, radius, np.zeros(1, np.bool_), 1, 1e-3, vertices, triangles, grid)
print(f_tri.size, sum(_count_or_fill_facets.stats.cache_hits.values()))
"""


def run_probe(root):
    env = dict(os.environ, PYTHONPATH=str(root), NUMBA_NUM_THREADS="1")
    env.pop("NUMBA_CACHE_DIR", None)
    out = subprocess.run([sys.executable, "-c", PROBE.format(root=str(root))], cwd=root, env=env,
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    candidates, cache_hits = out.stdout.split()
    return int(candidates), int(cache_hits)


def test_editing_a_callee_in_another_module_recompiles_its_cached_callers(tmp_path):
    package = tmp_path / "de_domain"
    shutil.copytree(Path(de_domain.__file__).parent, package, ignore=shutil.ignore_patterns("__pycache__"))
    # distance 0.5 mm from the sphere's surface, within the 1 mm skin: one candidate
    assert run_probe(tmp_path) == (1, 0)   # compiled and cached
    assert run_probe(tmp_path) == (1, 1)   # loaded from the cache (one signature: count and fill)
    walls = package / "walls.py"
    source = walls.read_text()
    original = "    return (q.x - px) ** 2 + (q.y - py) ** 2 + (q.z - pz) ** 2\n"
    assert source.count(original) == 1
    walls.write_text(source.replace(original, "    return 4.0 * ((q.x - px) ** 2 + (q.y - py) ** 2"
                                              " + (q.z - pz) ** 2)\n"))
    # the distance now reads twice as large, 3 mm > r + skin: the edited callee runs
    assert run_probe(tmp_path) == (0, 0)
    stale = [p.name for p in (package / "__pycache__").iterdir() if p.name.startswith("numba-")]
    assert len(stale) == 1  # the directory of the old digest was removed


SCENE = """
import hashlib
import numpy as np
import de_domain
from de_domain import Engine, FacetMesh, Material, Particles, PlaneWall
from de_domain.fused import advance
from de_domain.packing import random_cloud

assert de_domain.__file__.startswith({root!r}), de_domain.__file__
sand = Material(density=2650.0, young=1e7, friction=0.5, restitution=0.5, stiffness_ratio=4.0)
steel = Material(density=7800.0, young=1e7, poisson=0.3, friction=0.0, restitution=0.5)
L = 0.012
radii = np.random.default_rng(2026).uniform(0.8e-3, 1.2e-3, 300)
positions, radii = random_cloud(radii, (0.0, 0.0, 0.0), (L, L, 3.5 * L), seed=2026)
particles = Particles.from_spheres(positions, radii, np.zeros(len(radii), np.int32), [sand, steel])
floor = FacetMesh([[0, 0, 0], [L, 0, 0], [L, L, 0], [0, L, 0]], [[0, 1, 2], [0, 2, 3]], material=0)
sides = [PlaneWall((0, 0, 0), (1, 0, 0), material=1), PlaneWall((L, 0, 0), (-1, 0, 0), material=1),
         PlaneWall((0, 0, 0), (0, 1, 0), material=1), PlaneWall((0, L, 0), (0, -1, 0), material=1)]
engine = Engine(particles, [sand, steel], walls=sides, facets=[floor], gravity=(0.0, 0.0, -9.81),
                safety_factor=0.3, local_damping=0.3)
engine.run(6000)
state = np.concatenate([engine.particles.pos.ravel(), engine.particles.vel.ravel(), floor.force.ravel()])
print(hashlib.sha1(state.tobytes()).hexdigest(), sum(advance.stats.cache_hits.values()))
"""


@pytest.mark.slow  # compiles every DEM kernel into an empty cache (~1 min)
def test_a_process_that_compiles_runs_the_same_bits_as_one_that_loads_the_cache(tmp_path):
    """300 spheres settling on a facet floor inside plane walls, 6,000 steps: the process
    that compiles every kernel and the next one, which loads them, end bit-identical (with
    LLVM's FMA contraction on, they parted after about 4,000 steps)."""
    shutil.copytree(Path(de_domain.__file__).parent, tmp_path / "de_domain",
                    ignore=shutil.ignore_patterns("__pycache__"))
    env = dict(os.environ, PYTHONPATH=str(tmp_path), NUMBA_NUM_THREADS="1")
    env.pop("NUMBA_CACHE_DIR", None)
    runs = [subprocess.run([sys.executable, "-c", SCENE.format(root=str(tmp_path))], cwd=tmp_path, env=env,
                           capture_output=True, text=True, timeout=900) for _ in range(2)]
    assert all(r.returncode == 0 for r in runs), runs[0].stderr + runs[1].stderr
    (compiled, hits_first), (loaded, hits_second) = (r.stdout.split() for r in runs)
    assert (int(hits_first), int(hits_second)) == (0, 1)
    assert compiled == loaded
