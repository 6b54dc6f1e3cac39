"""A DEM scene driven from Python: sand poured into a box, settled, measured, saved and resumed.

The story, top to bottom (docs/scripting.md §1–§6 explain each call):

1. two materials (grains, steel) and 300 spheres in a random non-overlapping cloud;
2. a box of four frictionless plane walls on a floor that is a triangle facet mesh;
3. the engine (linear contact law, gravity, a little local damping);
4. settling, in chunks of steps, until the unbalanced force ratio is small;
5. the standard diagnostics: porosity and void ratio of a measuring box, coordination
   number, Love–Weber stress, the energy balance, the contact list;
6. ParaView frames (VTU particles + facets, and a PVD index over time);
7. a checkpoint, and a run resumed from it that is bit-identical to the uninterrupted one.

Run (after ``make setup``; the first run compiles the Numba kernels, which takes a while
once, later runs load them from the on-disk cache)::

    .venv/bin/python examples/dem_scene.py [OUT_DIR]

``OUT_DIR`` defaults to a new temporary folder. The last line printed is
``resumed run bit-identical: True`` (the script fails with an AssertionError otherwise).
"""
import sys
import tempfile
from pathlib import Path

import numpy as np

from cosim.outputs import PvdCollection
from de_domain import Engine, FacetMesh, Material, Particles, PlaneWall, diagnostics
from de_domain.diagnostics import BoxRegion, SphereRegion
from de_domain.io import write_frame
from de_domain.packing import random_cloud, save_packing

out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(tempfile.mkdtemp(prefix="dem_scene_"))
out.mkdir(parents=True, exist_ok=True)

# 1. Materials (SI units) and spheres. Material ids index the list: 0 = sand, 1 = steel.
sand = Material(density=2650.0, young=1e7, poisson=0.25, friction=0.5, restitution=0.5, stiffness_ratio=4.0)
steel = Material(density=7800.0, young=1e7, poisson=0.3, friction=0.0, restitution=0.5)
materials = [sand, steel]
L = 0.012  # box side [m]
rng = np.random.default_rng(2026)
positions, radii = random_cloud(rng.uniform(0.8e-3, 1.2e-3, 300), (0.0, 0.0, 0.0), (L, L, 3.5 * L), seed=2026)
particles = Particles.from_spheres(positions, radii, material_ids=np.zeros(len(radii), np.int32), materials=materials)

# 2. Boundaries: the floor is a facet mesh (two triangles; FacetMesh.from_file reads STL or
#    gmsh files the same way), the four sides are infinite planes with normals into the box.
floor = FacetMesh([[0, 0, 0], [L, 0, 0], [L, L, 0], [0, L, 0]], [[0, 1, 2], [0, 2, 3]], material=0)
sides = [PlaneWall((0, 0, 0), (1, 0, 0), material=1), PlaneWall((L, 0, 0), (-1, 0, 0), material=1),
         PlaneWall((0, 0, 0), (0, 1, 0), material=1), PlaneWall((0, L, 0), (0, -1, 0), material=1)]

# 3. The engine: dt = safety_factor x the critical time step unless dt= is given.
engine = Engine(particles, materials, walls=sides, facets=[floor], contact_law="linear",
                gravity=(0.0, 0.0, -9.81), safety_factor=0.3, local_damping=0.3)
print(f"{particles.n} spheres, dt = {engine.dt:.3e} s (critical {engine.critical_timestep():.3e} s)")

# 4. Settle: run in chunks, watch the unbalanced force ratio (YADE's unbalancedForce),
#    write a ParaView frame every chunk.
frames = PvdCollection(out / "particles.pvd")
frames.add(engine.time, write_frame(out / "frames", engine, engine.step_count))
print(f"{'t [s]':>9} {'steps':>6} {'unbalanced':>10} {'Z':>5} {'kinetic [J]':>11}")
while True:
    engine.run(5000)
    ratio = diagnostics.unbalanced_force_ratio(engine)
    print(f"{engine.time:9.4f} {engine.step_count:6d} {ratio:10.3g} {diagnostics.coordination_number(engine):5.2f} "
          f"{diagnostics.kinetic_energy(engine):11.3e}")
    frames.add(engine.time, write_frame(out / "frames", engine, engine.step_count))
    if (ratio < 0.02 and engine.time > 0.05) or engine.step_count >= 150000:
        break
assert ratio < 0.05, f"the packing did not settle (unbalanced force ratio {ratio:.3g})"

# 5. Diagnostics of the settled packing.
top = float(np.max(particles.pos[:, 2] + particles.radius))
middle = BoxRegion((0.2 * L, 0.2 * L, 0.2 * top), (0.8 * L, 0.8 * L, 0.7 * top))
print(f"packing height {top * 1e3:.2f} mm; measuring box: porosity {diagnostics.porosity(engine, middle):.3f}, "
      f"void ratio {diagnostics.void_ratio(engine, middle):.3f}; measuring sphere r = 0.4 L: void ratio "
      f"{diagnostics.void_ratio(engine, SphereRegion((L / 2, L / 2, 0.45 * top), 0.4 * L)):.3f}")
sigma = diagnostics.love_weber_stress(engine, BoxRegion((0, 0, 0), (L, L, top)))
weight = float(np.sum(particles.mass) * 9.81)
print(f"Love-Weber stress of the whole packing (compression +): sigma_zz = {sigma[2, 2]:.1f} Pa (a layer "
      f"under its own weight averages W / 2A = {weight / (2 * L * L):.1f} Pa), sigma_xx = {sigma[0, 0]:.1f} Pa")
e = engine.energy()
print(f"energy: kinetic {e['kinetic']:.3e} J, dissipated {e['dissipated']:.3e} J (friction {e['friction']:.3e}, "
      f"contact damping {e['contact_damping']:.3e}, background {e['background_damping']:.3e}), "
      f"residual {e['residual']:.2e} J = {abs(e['residual']) / e['dissipated']:.1e} of the dissipation")
c = engine.contacts()
normal_force = np.abs(np.einsum("ij,ij->i", c["force"], c["normal"]))
print(f"contacts: {len(c['i'])} sphere pairs (largest normal force {normal_force.max():.3g} N), "
      f"{len(c['wall_particle'])} on the side walls, {len(c['facet_particle'])} on the floor facets")
# floor.force is the force of the particles on the mesh (down); the frictionless side walls carry no weight
print(f"the floor carries {-floor.force[2]:.4g} N of the grains' weight {weight:.4g} N")
assert abs(-floor.force[2] - weight) < 0.05 * weight
save_packing(out / "settled_packing.npz", particles.pos, particles.radius)  # reusable as a packing file

# 6. Checkpoint, then compare an uninterrupted continuation with one resumed from the file.
checkpoint = out / "settled.npz"
engine.save_checkpoint(checkpoint)
sides[1].velocity = (-0.02, 0.0, 0.0)  # squeeze the packing a little from one side: contacts change
engine.run(2000)
resumed = Engine.load_checkpoint(checkpoint)
resumed.walls[1].velocity = (-0.02, 0.0, 0.0)  # the loaded engine has its own wall objects
resumed.run(2000)
same = all(np.array_equal(getattr(engine.particles, k), getattr(resumed.particles, k))
           for k in ("pos", "vel", "angvel", "force", "torque"))
same = same and engine.energy() == resumed.energy() and np.array_equal(engine.walls[1].force, resumed.walls[1].force)
print(f"frames and checkpoint in {out}")
print(f"resumed run bit-identical: {same}")
assert same
