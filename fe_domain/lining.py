"""Section forces of a ring of FE cells (a tunnel lining): the thrust N(θ) and the bending
moment M(θ) per unit length of the tunnel.

Around the ring, θ is measured in its section plane from the crown (the ``up`` direction,
θ = 0) towards the side ``axis × up`` (θ = 90°: the springline) to the invert (180°). A cut
at θ takes the ring's cells whose centres lie within 30° before θ (side A) and within 30°
after it (side B); the force that side B exerts on side A is the sum, over the nodes the two
sides share, of the B cells' nodal forces, F = −Σ_{e∈B} ∫_e Bᵀσ (the element's nodal internal
forces, with the whole stress σ: 2G dev ε(u) + p I plus any initial stress). Its moment is
taken about the point of the mid-radius r_m at θ, and with t̂ the tangent (towards B) and â
the axis

    N = −F·t̂                      (compression positive)
    M = −Σ (x_a − x_m) × F_a · â    (positive when the intrados is in tension)

divided by the ring's length along the axis (N/m and N·m/m: per metre of tunnel). These are
the resultants the discrete ring transmits, exact by equilibrium for any stress field the
cells carry (the "nodal force" method of section forces), rather than a fit of its
stresses: linear tetrahedra represent bending stress across a lining two or three cells thick
poorly, while their nodal forces still balance. The cut follows the cells' faces, within
about a cell of the radial line at θ.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import ufl
from dolfinx import fem
from mpi4py import MPI

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


class SectionGauge:
    """Reads N(θ) and M(θ) of the cells of ``group`` of ``solid`` around ``ring`` (module
    docstring), the geometry and the stress expression set up once; :meth:`forces` is
    collective (every rank's owned cells enter every cut). A cut at θ takes side A as the cells
    within ``SIDE`` before θ and side B within ``SIDE`` after it, so it works anywhere on a
    whole ring or on the part of one a model of symmetry holds."""

    SIDE = np.radians(30.0)

    def __init__(self, solid, group: str, ring: Ring):
        self.solid, self.group, self.ring = solid, group, ring
        owned = solid.tagged_mesh.cells(group)
        self.cells = owned[owned < solid.mesh.topology.index_map(3).size_local]
        cell_nodes = solid.Q.dofmap.list.array.reshape(-1, 4)[self.cells]
        x = solid.node_coordinates[cell_nodes]                              # (cells, 4, 3)
        edges = x[:, 1:] - x[:, :1]
        self.volume = solid.cell_volumes[self.cells]
        self.gradients = np.empty_like(x)                                   # ∇N_a of each cell
        self.gradients[:, 1:] = np.linalg.inv(np.transpose(edges, (0, 2, 1)))
        self.gradients[:, 0] = -self.gradients[:, 1:].sum(axis=1)
        axis, up, side = ring.frame()
        offset = x.mean(axis=1) - np.asarray(ring.centre, float)
        parts = solid.comm.allgather((solid.global_node_index[cell_nodes], np.arctan2(offset @ side, offset @ up), x))
        self.nodes, self.angle, self.x = (np.concatenate(part) for part in zip(*parts, strict=True))
        self.length = float(np.ptp(self.x.reshape(-1, 3) @ axis))
        space = fem.TensorFunctionSpace(solid.mesh, ("DG", 0))
        stress = forms.deviatoric_stress(solid.u, solid.G) + solid.pressure_form * ufl.Identity(3)
        if solid.initial_stress is not None:
            stress = stress + solid.initial_stress
        self._stress = fem.Function(space)
        self._expression = fem.Expression(stress, space.element.interpolation_points())
        self._blocks = space.dofmap.list.array[self.cells]

    def cell_stresses(self) -> np.ndarray:
        """The whole stress of this rank's cells of the ring (cells, 3, 3): 2G dev ε(u) + p I (the
        displacement formulation: p = K div u) plus the initial stress at the solid's time (p at
        the cell's centre: the mean of its nodes' values)."""
        if self.solid.initial_stress is not None:
            self.solid.update_initial_stress()
        self._stress.interpolate(self._expression)
        return self._stress.x.array.reshape(-1, 3, 3)[self._blocks]

    def angles_deg(self, spacing_deg: float) -> np.ndarray:
        """Cut angles every ``spacing_deg`` from ``spacing_deg / 2``, where the ring has cells on
        both sides within ``SIDE`` (all around a whole ring; inside a part of one)."""
        candidates = np.arange(0.5 * spacing_deg, 360.0, spacing_deg)
        wrapped = np.degrees(np.angle(np.exp(1j * np.radians(candidates))))
        return np.sort([a for a in wrapped if len(self._shared(np.radians(a)))])

    def _sides(self, target):
        delta = np.angle(np.exp(1j * (self.angle - target)))
        return (delta < 0) & (delta >= -self.SIDE), (delta >= 0) & (delta < self.SIDE)

    def _shared(self, target):
        before, after = self._sides(target)
        return np.intersect1d(self.nodes[before], self.nodes[after])

    def forces(self, angles_deg) -> SectionForces:
        """N and M at ``angles_deg`` from the crown."""
        nodal = self.volume[:, None, None] * np.einsum("cij,caj->cai", self.cell_stresses(), self.gradients)
        nodal = np.concatenate(self.solid.comm.allgather(nodal))
        axis, up, side = self.ring.frame()
        centre = np.asarray(self.ring.centre, float)
        mid = 0.5 * (self.ring.inner_radius + self.ring.outer_radius)
        thrust, moment = [], []
        for target in np.radians(np.asarray(angles_deg, float)):
            shared = self._shared(target)
            if len(shared) == 0:
                raise ValueError(f"lining '{self.group}': no cut at {np.degrees(target):.1f}° "
                                 "(it lies outside the ring's cells)")
            on_cut = np.isin(self.nodes, shared) & self._sides(target)[1][:, None]
            force = -nodal[on_cut]                                          # B's cells on the shared nodes
            tangent = np.cos(target) * side - np.sin(target) * up
            point = centre + mid * (np.sin(target) * side + np.cos(target) * up)
            arm = self.x[on_cut] - point
            arm -= np.outer(arm @ axis, axis)                               # in the section plane
            thrust.append(-force.sum(axis=0) @ tangent / self.length)
            moment.append(-np.cross(arm, force).sum(axis=0) @ axis / self.length)
        return SectionForces(np.asarray(angles_deg, float), np.array(thrust), np.array(moment))


class DiameterGauge:
    """The change of the ring's inside diameters, vertical (crown to invert) and horizontal
    (springline to springline), over the intrados diameter D = 2 r_i: ΔD_v / D and ΔD_h / D,
    lengthening positive; the ovalisation is ΔD_h / D − ΔD_v / D. Each diameter is read from
    the displacements of the two intrados nodes of ``group`` nearest its ends (at the ring's
    mid-length along the axis); where a model of symmetry holds half the ring (no node within
    ``REACH`` of an end), the other end mirrors the one it has. Collective (:meth:`changes`)."""

    REACH = np.radians(5.0)
    ENDS = {"crown": 0.0, "springline": 0.5 * np.pi, "invert": np.pi, "other_springline": -0.5 * np.pi}

    def __init__(self, solid, group: str, ring: Ring):
        self.solid, self.ring = solid, ring
        owned = solid.tagged_mesh.cells(group)
        nodes = np.unique(solid.Q.dofmap.list.array.reshape(-1, 4)[owned])
        nodes = nodes[nodes < solid.n_owned_nodes]
        axis, up, side = ring.frame()
        offset = solid.node_coordinates[nodes] - np.asarray(ring.centre, float)
        along = offset @ axis
        radial = offset - np.outer(along, axis)
        on_intrados = np.linalg.norm(radial, axis=1) < ring.inner_radius + 1e-6 * ring.outer_radius
        angle = np.arctan2(radial @ side, radial @ up)
        middle = 0.5 * (solid.comm.allreduce(float(along.min(initial=np.inf)), op=MPI.MIN)
                        + solid.comm.allreduce(float(along.max(initial=-np.inf)), op=MPI.MAX))
        self.ends = {}   # end: (this rank's node or -1)
        for end, target in self.ENDS.items():
            miss = np.abs(np.angle(np.exp(1j * (angle - target))))
            score = np.where(on_intrados & (miss < self.REACH), miss * ring.inner_radius + np.abs(along - middle),
                             np.inf)
            best = int(np.argmin(score)) if len(score) else -1
            mine = float(score[best]) if best >= 0 else np.inf
            winner = solid.comm.allreduce((mine, solid.comm.rank), op=MPI.MINLOC)
            found = winner[0] < np.inf
            self.ends[end] = (nodes[best] if found and winner[1] == solid.comm.rank else -1, found)

    def _displacement(self, end):
        node, found = self.ends[end]
        local = self.solid.displacement[node] if node >= 0 else np.zeros(3)
        return self.solid.comm.allreduce(local) if found else None

    def changes(self) -> tuple[float, float]:
        """(ΔD_v / D, ΔD_h / D) now."""
        axis, up, side = self.ring.frame()
        u = {end: self._displacement(end) for end in self.ENDS}
        if u["crown"] is None or u["springline"] is None:
            raise ValueError("the lining has no intrados node at its crown or springline")
        invert = u["invert"] if u["invert"] is not None else u["crown"] - 2.0 * (u["crown"] @ up) * up
        other = u["other_springline"] if u["other_springline"] is not None \
            else u["springline"] - 2.0 * (u["springline"] @ side) * side
        diameter = 2.0 * self.ring.inner_radius
        return float((u["crown"] - invert) @ up / diameter), float((u["springline"] - other) @ side / diameter)


def section_forces(solid, group: str, ring: Ring, angles_deg) -> SectionForces:
    """N(θ) and M(θ) of the cells of ``group`` at ``angles_deg`` once (:class:`SectionGauge`)."""
    return SectionGauge(solid, group, ring).forces(angles_deg)


def ring_of_cells(solid, group: str, centre, axis, up) -> Ring:
    """The :class:`Ring` of the cells of ``group`` about the line through ``centre`` along
    ``axis``: its inner and outer radii the nodes' least and greatest distances from the line
    (collective)."""
    owned = solid.tagged_mesh.cells(group)
    nodes = np.unique(solid.Q.dofmap.list.array.reshape(-1, 4)[owned])
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    offset = solid.node_coordinates[nodes] - np.asarray(centre, float)
    distance = np.linalg.norm(offset - np.outer(offset @ a, a), axis=1)
    inner = solid.comm.allreduce(float(distance.min(initial=np.inf)), op=MPI.MIN)
    outer = solid.comm.allreduce(float(distance.max(initial=0.0)), op=MPI.MAX)
    return Ring(tuple(centre), tuple(axis), tuple(up), inner, outer)


@dataclass(frozen=True)
class LinedTunnel:
    """A circular lining of mid-radius ``radius`` and thickness ``thickness`` (m) in elastic ground
    (``ground_E``, ``ground_nu``), the lining ``lining_E``, ``lining_nu``; in-situ stress
    σ_v = ``pressure`` (compression positive, Pa), σ_h = ``K`` σ_v."""
    radius: float
    thickness: float
    ground_E: float
    ground_nu: float
    lining_E: float
    lining_nu: float
    pressure: float
    K: float


def einstein_schwartz(tunnel: LinedTunnel, angles_deg):
    """Thrust and moment (N/m, N·m/m) of a lining tied to the ground ("no slip") under the
    excavation loading, at θ from the crown (Einstein & Schwartz, J. Geotech. Eng. Div. ASCE
    105(GT4), 1979; as in the FLAC verification "lined circular tunnel"; plane strain, per
    metre of tunnel, a thin lining in a deep tunnel), with ψ = 90° − θ from the springline:

        C* = E R (1 − ν_l²) / (E_l t (1 − ν²)),   F* = E R³ (1 − ν_l²) / (E_l t³/12 (1 − ν²))
        a0* = C* F* (1 − ν) / (C* + F* + C* F* (1 − ν))
        β = ((6 + F*) C* (1 − ν) + 2 F* ν) / (3 F* + 3 C* + 2 C* F* (1 − ν))
        b2* = C* (1 − ν) / (2 (C* (1 − ν) + 4ν − 6β − 3β C* (1 − ν))),   a2* = β b2*
        T = p R [½ (1 + K)(1 − a0*) + ½ (1 − K)(1 + 2 a2*) cos 2ψ]        (compression positive)
        M = −p R² ¼ (1 − K)(1 − 2 a2* + 2 b2*) cos 2ψ     (this module's sign: intrados in tension +)

    Returns (thrust, moment, C*, F*)."""
    E, nu, El, nul = tunnel.ground_E, tunnel.ground_nu, tunnel.lining_E, tunnel.lining_nu
    t, R, p, K = tunnel.thickness, tunnel.radius, tunnel.pressure, tunnel.K
    c = E * R * (1 - nul**2) / (El * t * (1 - nu**2))
    f = E * R**3 * (1 - nul**2) / (El * t**3 / 12 * (1 - nu**2))
    a0 = c * f * (1 - nu) / (c + f + c * f * (1 - nu))
    beta = ((6 + f) * c * (1 - nu) + 2 * f * nu) / (3 * f + 3 * c + 2 * c * f * (1 - nu))
    b2 = c * (1 - nu) / (2 * (c * (1 - nu) + 4 * nu - 6 * beta - 3 * beta * c * (1 - nu)))
    a2 = beta * b2
    psi = np.radians(90.0 - np.asarray(angles_deg, float))
    thrust = p * R * (0.5 * (1 + K) * (1 - a0) + 0.5 * (1 - K) * (1 + 2 * a2) * np.cos(2 * psi))
    moment = -p * R**2 * 0.25 * (1 - K) * (1 - 2 * a2 + 2 * b2) * np.cos(2 * psi)
    return thrust, moment, c, f
