"""Section forces of a ring of FE cells (a tunnel lining): the thrust N(θ) and the bending
moment M(θ) per unit length of the tunnel, from the cells' stresses.

Around the ring, θ is measured in its section plane from the crown (the ``up`` direction,
θ = 0) towards the side ``axis × up`` (θ = 90°: the springline) to the invert (180°). At an
angle θ the hoop stress σ_θθ = t̂ᵀ σ t̂ (t̂ the ring's tangent) of the cells whose centres lie
within ``window`` of θ is fitted by weighted least squares (the cells' volumes as weights)
with a line across the thickness, σ_θθ ≈ a + b (r − r_m), r_m the mid-radius; then

    N = −∫ σ_θθ dr = −a t                    (compression positive)
    M = −∫ σ_θθ (r − r_m) dr = −b t³ / 12    (positive when the intrados is in tension)

over the thickness t (N/m and N·m/m: per metre of tunnel). The stress of a P1 cell is
constant, so the fit needs cells at two radii at least: a lining two or more cells thick.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import ufl
from dolfinx import fem

from fe_domain import forms


@dataclass(frozen=True)
class Ring:
    """A ring's place: ``centre`` a point of its axis, ``axis`` along the tunnel, ``up`` in its
    section plane (θ = 0), radii of its inside (intrados) and outside (extrados), in m."""
    centre: tuple
    axis: tuple
    up: tuple
    inner_radius: float
    outer_radius: float

    def frame(self):
        """Unit vectors (axis, up, side = axis × up), up made normal to the axis."""
        axis = np.asarray(self.axis, float) / np.linalg.norm(self.axis)
        up = np.asarray(self.up, float) - np.dot(self.up, axis) * axis
        up /= np.linalg.norm(up)
        return axis, up, np.cross(axis, up)


@dataclass(frozen=True)
class SectionForces:
    """N(θ) and M(θ) around a ring (:mod:`fe_domain.lining`)."""
    angle_deg: np.ndarray
    thrust: np.ndarray      # N/m, compression positive
    moment: np.ndarray      # N·m/m, positive when the intrados is in tension


def cell_stresses(solid) -> np.ndarray:
    """The whole stress of each local cell, (cells, 3, 3): 2G dev ε(u) + p I, plus the solid's
    initial stress at its time (p at the cell's centre: the mean of its nodes' values)."""
    space = fem.TensorFunctionSpace(solid.mesh, ("DG", 0))
    stress = forms.deviatoric_stress(solid.u, solid.G) + solid.p * ufl.Identity(3)
    if solid.initial_stress is not None:
        solid.update_initial_stress()
        stress = stress + solid.initial_stress
    field = fem.Function(space)
    field.interpolate(fem.Expression(stress, space.element.interpolation_points()))
    return field.x.array.reshape(-1, 3, 3)[space.dofmap.list.array]


def section_forces(solid, group: str, ring: Ring, angles_deg, window_deg: float) -> SectionForces:
    """N(θ) and M(θ) of the cells of ``group`` at ``angles_deg`` (module docstring); collective
    (every rank's owned cells enter every fit)."""
    owned = solid.tagged_mesh.cells(group)
    owned = owned[owned < solid.mesh.topology.index_map(3).size_local]
    nodes = solid.node_coordinates[solid.Q.dofmap.list.array.reshape(-1, 4)[owned]]   # (cells, 4, 3)
    edges = nodes[:, 1:] - nodes[:, :1]
    volume = np.abs(np.einsum("ij,ij->i", edges[:, 0], np.cross(edges[:, 1], edges[:, 2]))) / 6.0
    axis, up, side = ring.frame()
    offset = nodes.mean(axis=1) - np.asarray(ring.centre, float)
    offset -= np.outer(offset @ axis, axis)
    angle = np.arctan2(offset @ side, offset @ up)
    radius = np.linalg.norm(offset, axis=1)
    tangent = np.outer(np.cos(angle), side) - np.outer(np.sin(angle), up)
    hoop = np.einsum("ci,cij,cj->c", tangent, cell_stresses(solid)[owned], tangent)
    gathered = solid.comm.allgather(np.column_stack([angle, radius, hoop, volume]))
    angle, radius, hoop, volume = np.concatenate(gathered).T
    mid, thickness = 0.5 * (ring.inner_radius + ring.outer_radius), ring.outer_radius - ring.inner_radius
    thrust, moment = [], []
    for target in np.radians(np.asarray(angles_deg, float)):
        near = np.abs(np.angle(np.exp(1j * (angle - target)))) <= 0.5 * np.radians(window_deg)
        if near.sum() < 2 or np.ptp(radius[near]) < 0.25 * thickness:
            raise ValueError(f"lining '{group}': the cells within {window_deg}° of {np.degrees(target):.1f}° do not "
                             "span its thickness (a lining two or more cells thick, or a wider window)")
        design = np.column_stack([np.ones(near.sum()), radius[near] - mid]) * np.sqrt(volume[near])[:, None]
        (a, b), *_ = np.linalg.lstsq(design, hoop[near] * np.sqrt(volume[near]), rcond=None)
        thrust.append(-a * thickness)
        moment.append(-b * thickness ** 3 / 12.0)
    return SectionForces(np.asarray(angles_deg, float), np.array(thrust), np.array(moment))

