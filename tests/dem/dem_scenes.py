"""Scenes shared by the DEM tests (a module, not conftest.py: test files import from it, and
pytest keeps only one module named ``conftest`` importable at a time)."""
import numpy as np

from de_domain import Engine, Material, Particles, PlaneWall


def box_gas(n_side=10, friction=0.0, restitution=1.0, speed=1.0, gravity=(0.0, 0.0, 0.0), walls=True,
            seed=0, spacing=2.4e-3, radius=1e-3, **engine_kw):
    """n_side³ spheres on a jittered lattice with random velocities, in a box of six planes."""
    rng = np.random.default_rng(seed)
    grid = np.stack(np.meshgrid(*[np.arange(n_side) * spacing] * 3, indexing="ij"), -1).reshape(-1, 3)
    pos = grid + spacing / 2 + rng.uniform(-0.1, 0.1, grid.shape) * (spacing - 2 * radius)
    radii = radius * rng.uniform(0.9, 1.0, len(pos))
    mat = [Material(density=2650.0, young=5e7, friction=friction, restitution=restitution)]
    vel = rng.normal(0.0, speed, pos.shape)
    p = Particles.from_spheres(pos, radii, materials=mat, velocities=vel)
    p.angvel[:] = rng.normal(0.0, speed / radius, pos.shape)
    L = n_side * spacing
    planes = []
    if walls:
        for d in range(3):
            normal = np.zeros(3)
            normal[d] = 1.0
            planes += [PlaneWall(np.zeros(3), normal), PlaneWall(normal * L, -normal)]
    return Engine(p, mat, walls=planes, gravity=gravity, **engine_kw)
