"""de_domain — Numba discrete element method of spheres, plane walls and triangle
facets (docs/design.md §2). Knows nothing of DOLFINx.

Public API
----------
``Material(density=2650, young=1e8, poisson=0.25, friction=0.5, restitution=0.5,
stiffness_ratio=1.5, rolling_stiffness=0.0, rolling_friction=0.0)``
    Frozen dataclass; pair values by the mixing rules in ``de_domain.materials``.

``Particles(pos, radius, mass, inertia=None, vel=None, angvel=None, material=None, group=None, n_owned=None)``
``Particles.from_spheres(positions, radii, material_ids=None, materials=None, velocities=None)``
    Struct of arrays: ``pos vel angvel force torque`` (n, 3); ``radius mass inertia`` (n,);
    ``material group`` (n,) int32; ``blocked prescribed`` (n, 6) bool (x y z rx ry rz);
    ``prescribed_velocity`` (n, 6); ``n``, ``n_owned`` (owned first, then ghosts).

``PlaneWall(point, normal, material=0, velocity=(0, 0, 0))``
    ``.point`` (movable between steps; work is booked), ``.velocity``, ``.force``
    (total force of the particles on the wall, last step).

``FacetMesh(vertices, triangles, material=0)``, ``FacetMesh.from_file(path, material=0, physical=None)``,
``FacetMesh.from_stl(path)``,
``FacetMesh.from_gmsh(path, physical=None)``
    ``.velocity`` (rigid translation), ``.set_vertex_state(positions, velocities)``,
    ``.vertex_force`` (nv, 3), ``.vertex_impulse`` (nv, 3), ``.reset_impulse()``,
    ``.force``; ``.source_nodes`` (gmsh node ids of the vertices).

``Engine(particles, materials, walls=(), facets=(), contact_law="linear"|"hertz",
gravity=(0, 0, -9.81), dt=None, safety_factor=0.3, local_damping=0.0,
viscous_damping=0.0, skin=None, comm=None, clumps=None)``
    ``.step()``, ``.run(nsteps)``, ``.time``, ``.step_count``, ``.dt``,
    ``.critical_timestep()``, ``.energy()`` (dict incl. ``residual``),
    ``.contacts()`` (dict of arrays), ``.memory_bytes()``, ``.save_checkpoint(path)``,
    ``Engine.load_checkpoint(path)``, ``.clumps`` and ``.clump_rows()`` (each local row's clump).

``de_domain.clumps``: ``ClumpTemplate(centres, radii)`` (mass properties of the union of the
members, principal frame), ``ClumpTemplate.line(count, aspect_ratio, radius)``,
``Clumps.place(templates, template_of, centres, orientations, materials, ...)`` → (particles,
clumps) for ``Engine(..., clumps=clumps)`` (also with ``comm``: a rank advances the clumps it owns a
member of; docs/design.md §2.19);
``ClumpPacking`` (clumps between engines: templates, sizes, places, orientations; a specimen's
``clumps``) and ``clump_cloud``. ``de_domain.deposition.generate(method, diameters, settings,
shapes=GrainShapes(templates, shares))`` makes a specimen of clumped grains.

``de_domain.diagnostics`` (each takes the engine, some a region): ``unbalanced_force_ratio``, ``kinetic_energy``,
``coordination_number``, ``solid_volume``, ``porosity``, ``void_ratio``,
``love_weber_stress`` with ``BoxRegion(lo, hi)`` / ``SphereRegion(center, radius)``, ``grain_radii``;
a clump counts as one grain.

``de_domain.io``: ``write_particles_vtu(path, particles, clump=None, ids=None)``, ``write_facets_vtu(path, mesh)``,
``write_frame(directory, engine, step)`` (distributed: a piece a rank and a ``.pvtu``),
``read_frame(path)`` (a ``.vtu`` or ``.pvtu`` back in global-id order).

Performance notes: ``Engine.run(n)`` is one compiled loop (``de_domain.fused``) with
two parallel regions per step that returns to Python only to rebuild the Verlet
lists; plane walls and facet meshes (moving rigidly or with per-vertex velocities)
are inside it. The loops visit particles in a spatial (Morton) order, and runs of
8 steps or more work on copies of the particle arrays sorted that way (the public
arrays keep their order; they are written back after the run). Plane-wall contact
history is sparse (walls within r + skin). ``Engine.memory_bytes()`` lists the
bytes of every per-particle and per-contact array. ``de_domain.threading`` sets the
Numba threading defaults (omp layer; a short spin of idle workers when the threads fit
the cores, ``OMP_WAIT_POLICY=PASSIVE`` when they do not) on import, so
import de_domain before the first ``numba.set_num_threads``/parallel call.

Developer notes: kernels are ``numba.njit(cache=True)``, and their cache entries are
stamped with a digest of every de_domain source (``numba_support.kernel_cache``): an
edit anywhere in the package recompiles every kernel, so a cached caller never runs a
stale callee. The kernels take their state as the named tuples of
``de_domain.state``. Results are bit-identical for any Numba thread count, any Verlet
rebuild frequency and either storage path (fixed-order reductions, canonically
sorted neighbour lists; tests/dem/test_fused_kernels.py).
"""
from pathlib import Path as _Path

from numba_support import kernel_cache as _kernel_cache

from . import threading as _threading

_kernel_cache.install(_Path(__file__).parent)  # before the first njit(cache=True) kernel is defined
_threading.configure()  # before the first parallel launch (see de_domain/threading.py)

from .engine import Engine  # noqa: E402
from .materials import Material  # noqa: E402
from .particles import Particles  # noqa: E402
from .walls import FacetMesh, PlaneWall  # noqa: E402

__all__ = ["Engine", "FacetMesh", "Material", "Particles", "PlaneWall"]
