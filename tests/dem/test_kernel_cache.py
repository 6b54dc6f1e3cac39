"""Numba's on-disk cache never runs stale code (de_domain.kernel_cache): a cached kernel
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
f_start, f_tri = build_facet_list(pos, radius, 1, 1e-3, vertices, triangles, grid)
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
    original = "    return (q[0] - px) ** 2 + (q[1] - py) ** 2 + (q[2] - pz) ** 2\n"
    assert source.count(original) == 1
    walls.write_text(source.replace(original, "    return 4.0 * ((q[0] - px) ** 2 + (q[1] - py) ** 2"
                                              " + (q[2] - pz) ** 2)\n"))
    # the distance now reads twice as large, 3 mm > r + skin: the edited callee runs
    assert run_probe(tmp_path) == (0, 0)
    stale = [p.name for p in (package / "__pycache__").iterdir() if p.name.startswith("numba-")]
    assert len(stale) == 1  # the directory of the old digest was removed
