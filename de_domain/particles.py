"""Sphere state as a struct of arrays (docs/design.md §1.2, §2.1).

``ghost`` marks the entries that are copies of particles another MPI rank owns
(:mod:`de_domain.distributed`; a serial run has none): they are read by the
contacts of owned particles and never integrated. Every per-particle array has the
particle as its first axis, so migration is a fancy-index of each array
(:meth:`Particles.take`).
"""
from __future__ import annotations

import numpy as np

from .materials import material_arrays

ARRAY_FIELDS = (
    "pos", "vel", "angvel", "radius", "mass", "inertia", "material", "group",
    "blocked", "prescribed", "prescribed_velocity", "force", "torque",
)


class Particles:
    """Spheres: ``pos``/``vel``/``angvel``/``force``/``torque`` (n, 3) float64,
    ``radius``/``mass``/``inertia`` (n,), ``material``/``group`` (n,) int32,
    ``blocked`` (n, 6) bool for x, y, z, rx, ry, rz (that DOF keeps its velocity),
    ``prescribed`` (n, 6) bool with ``prescribed_velocity`` (n, 6) (that DOF moves
    at the given velocity). ``force``/``torque`` hold the resultant (contacts +
    gravity, before background damping) of the last step.

    Velocities are leapfrog half-step values v^{n−½} (docs/design.md §2.13).
    """

    def __init__(self, pos, radius, mass, inertia=None, vel=None, angvel=None, material=None,
                 group=None, n_owned=None):
        self.pos = np.ascontiguousarray(pos, dtype=np.float64).reshape(-1, 3).copy()
        n = self.pos.shape[0]
        self.radius = _vector(radius, n, "radius")
        self.mass = _vector(mass, n, "mass")
        self.inertia = 0.4 * self.mass * self.radius**2 if inertia is None else _vector(inertia, n, "inertia")
        self.vel = np.zeros((n, 3)) if vel is None else np.array(vel, dtype=np.float64).reshape(n, 3)
        self.angvel = np.zeros((n, 3)) if angvel is None else np.array(angvel, dtype=np.float64).reshape(n, 3)
        self.material = np.zeros(n, np.int32) if material is None else np.array(material, dtype=np.int32).reshape(n)
        self.group = np.zeros(n, np.int32) if group is None else np.array(group, dtype=np.int32).reshape(n)
        self.blocked = np.zeros((n, 6), dtype=np.bool_)
        self.prescribed = np.zeros((n, 6), dtype=np.bool_)
        self.prescribed_velocity = np.zeros((n, 6))
        self.force = np.zeros((n, 3))
        self.torque = np.zeros((n, 3))
        self.ghost = np.zeros(n, np.bool_)
        if n_owned is not None:
            self.ghost[int(n_owned):] = True
        if np.any(self.radius <= 0) or np.any(self.mass <= 0):
            raise ValueError("Particles: radius and mass must be > 0 for every particle")

    @classmethod
    def from_spheres(cls, positions, radii, material_ids=None, materials=None, velocities=None):
        """Spheres with m = ρ 4/3 π r³ and I = 2/5 m r² from each material's density."""
        positions = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
        n = positions.shape[0]
        radii = _vector(radii, n, "radii")
        material_ids = np.zeros(n, np.int32) if material_ids is None else np.asarray(material_ids, np.int32).reshape(n)
        if materials is None:
            raise ValueError("Particles.from_spheres: 'materials' (list of Material) is required for the density")
        density, _, _ = material_arrays(materials)
        if n and (material_ids.min() < 0 or material_ids.max() >= len(materials)):
            raise ValueError(f"Particles.from_spheres: material ids must be in [0, {len(materials) - 1}]")
        mass = density[material_ids] * 4.0 / 3.0 * np.pi * radii**3
        return cls(positions, radii, mass, vel=velocities, material=material_ids)

    @property
    def n(self):
        return self.pos.shape[0]

    @property
    def n_owned(self):
        """Entries that are not ghosts."""
        return int(self.n - np.count_nonzero(self.ghost))

    @property
    def owned(self):
        """Bool mask of the entries that are not ghosts."""
        return ~self.ghost

    def take(self, index, n_owned=None):
        """New Particles made of the entries ``index`` (migration / reordering)."""
        out = Particles.__new__(Particles)
        for name in ARRAY_FIELDS:
            setattr(out, name, getattr(self, name)[index].copy())
        out.ghost = np.zeros(out.pos.shape[0], np.bool_)
        if n_owned is not None:
            out.ghost[int(n_owned):] = True
        return out

    def arrays(self):
        return {name: getattr(self, name) for name in ARRAY_FIELDS}

    @classmethod
    def from_arrays(cls, arrays, n_owned):
        out = cls.__new__(cls)
        for name in ARRAY_FIELDS:
            setattr(out, name, np.array(arrays[name]))
        out.ghost = np.zeros(out.pos.shape[0], np.bool_)
        out.ghost[int(n_owned):] = True
        return out


def _vector(value, n, name):
    v = np.asarray(value, dtype=np.float64)
    if v.ndim == 0:
        return np.full(n, float(v))
    if v.shape != (n,):
        raise ValueError(f"Particles: '{name}' must have shape ({n},), got {v.shape}")
    return v.copy()
