"""Finite-element solid of the FE–DE co-simulation (docs/design.md §4), on DOLFINx 0.5.

    mesh.py      gmsh .geo/.msh → distributed mesh with tags addressed by physical-group name
    forms.py     UFL of the explicit mixed u–p formulation (one function per integral)
    boundary.py  materials, boundary conditions, loads and damping laws (plain records)
    explicit.py  ExplicitSolid: the 4-step central-difference u–p update, coupling arrays
    output.py    XDMF fields, energy and reaction CSV files
    build.py     build_solid(): the solver from plain (TOML-like) parameters

    compiled.py  the one-rank step as compiled loops (Numba; the default on one rank)

``fe_domain`` knows nothing of particles; the coupling (``cosim``) reads facet
triangles, node positions and velocities from ``ExplicitSolid`` and writes
``ExplicitSolid.external_force``.
"""
from pathlib import Path as _Path

from numba_support import kernel_cache as _kernel_cache

_kernel_cache.install(_Path(__file__).parent)  # before compiled.py's kernels are defined
