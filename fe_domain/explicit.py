"""Explicit mixed displacement–pressure solid on DOLFINx (docs/design.md §4).

Unknowns (all P1, nodal): u, v (vector), p (mean stress, tension positive), π
(projected pressure gradient, vector).  Lumped diagonal matrices M = ρ∫N,
M_p = ∫N/K, G̃ = ∫τN, with the orthogonal-sub-scale parameter
τ_e = α_τ h_e²/(2G) per element.  One step (central differences):

1. v^{n+½} = v^{n−½} + Δt M⁻¹ (f_ext − f_int(u^n, p^n) − f_damp),
   f_int = ∫ Bᵀ(s(u) + p I)
2. u^{n+1} = u^n + Δt v^{n+½}
3. p^{n+1} = p^n + M_p⁻¹ [Δt ∫ q div v^{n+½} − ∫ τ ∇q·(∇p^n + π^n)]
4. π^{n+1} = −G̃⁻¹ ∫ τ N ∇p^{n+1}

The material is linear elastic and small-strain, so each per-step integral is a
constant linear operator of the state.  They are assembled once, at construction,
from the bilinear forms of ``forms.py`` into PETSc matrices:

    f_int(u, p) = K_dev u + Bᵀ p        K_dev = ∫ s(N):∇N (BAIJ, 3×3 blocks), Bᵀ = ∫ N div N
    ∫ τ N ∇p    = P p                   P = ∫ τ N·∇N
    ∫ q div v   = (Bᵀ)ᵀ v               (transpose product, no extra matrix)
    ∫ τ ∇q·(∇p + π) = L p + Pᵀ π        L = ∫ τ ∇N·∇N

so a step is six sparse matrix–vector products plus nodal array operations, with
the same arithmetic as steps 1–4 (to round-off).  Step 4 needs only p^{n+1} and
is consumed first by step 3 of the next step, so it is evaluated at the start of
the next step, next to f_int (both read (u^{n+1}, p^{n+1})).  The products fill
the owned rows (PETSc fetches the off-rank inputs itself); forward ghost updates
of f_int and π, and of p after step 3's owned-node update, keep every nodal array
valid on owned and ghost nodes after a step.  ``formulation="displacement"``
drops p and π and uses f_int = K u, K = ∫ Bᵀ(s(N) + K div N I): the standard P1
element, which locks as ν → ½.

h_e is the smallest altitude of tetrahedron e (3 V_e / largest face area), used both
for τ_e and for the time step Δt = f_s min_e h_e / c_p,e, c_p = √((K + 4G/3)/ρ).

Stability of step 3 (measured; ``tests/fe/test_fe_stabilisation.py`` re-checks it).
The τ-term of step 3 is an explicit diffusion of p with no Δt in front: a pressure
mode is multiplied each step by 1 − α_τ (K/2G) λ, λ = O(1) a mesh eigenvalue of
h_e² M_p⁻¹-scaled ∫∇q·∇p, so it is stable only while α_τ K/G ≤ C, independent of
Δt and ρ.  Sweeps on the gmsh block (``meshes/block.geo``, unit cube, mesh sizes
0.25 and 0.125, f_s = 0.5, bottom fixed, undamped, 2000 steps from a random
velocity field) gave:

    ν = 0.3    (K/G = 2.17): stable α_τ ≤ 0.3,     blow-up α_τ ≥ 0.5
    ν = 0.499  (K/G = 500):  stable α_τ ≤ 0.0012,  blow-up α_τ ≥ 0.0015
    ν = 0.4999 (K/G = 5000): stable α_τ ≤ 0.00014, blow-up α_τ ≥ 0.0002

so C = (α_τ K/G)_max ≈ 0.6 (``STABILITY_CONSTANT``).  The default
``DEFAULT_ALPHA_TAU = 6e-4`` is stable for all ν ≤ 0.499 with a margin of 2; for
ν closer to ½ use ``stable_alpha_tau(nu)`` = ½ C G/K (same margin).
"""

from __future__ import annotations

import functools
from typing import Mapping, Sequence

import dolfinx
import dolfinx.cpp
import dolfinx.fem.petsc
import numpy as np
import ufl
from dolfinx import fem
from dolfinx.la import ScatterMode
from mpi4py import MPI
from petsc4py import PETSc

from fe_domain import compiled, forms, jit
from fe_domain.boundary import (
    BodyForce,
    Contraction,
    Fixed,
    GeostaticStress,
    LocalNonViscousDamping,
    MassProportionalDamping,
    Material,
    NormalPressure,
    PrescribedVelocity,
    Traction,
    UniformStress,
    constant,
)
from fe_domain.mesh import TaggedMesh
from numba_support.dispatch import CachedEntry

jit.install()   # DOLFINx's JIT: one short line on a cache miss, no compiler command lines

#: Measured stability constant of step 3: stable while α_τ K/G ≤ STABILITY_CONSTANT.
STABILITY_CONSTANT = 0.6
#: Default α_τ: stable up to ν = 0.499 (K/G ≈ 500) with a margin of 2.
DEFAULT_ALPHA_TAU = 6e-4


def stable_alpha_tau(nu: float, margin: float = 0.5) -> float:
    """α_τ = margin · C · G/K for Poisson ratio ν (C = STABILITY_CONSTANT)."""
    g_over_k = 3.0 * (1.0 - 2.0 * nu) / (2.0 * (1.0 + nu))
    return margin * STABILITY_CONSTANT * g_over_k


def _dot(a: np.ndarray, b: np.ndarray) -> float:
    """Σ a·b without BLAS: a threaded BLAS dot costs ~1 ms per call on a loaded machine."""
    return float(np.einsum("i,i->", a.ravel(), b.ravel()))


class ExplicitSolid:
    """Explicit mixed u–p (or pure-displacement) P1 solid; see the module docstring.

    Node arrays use the local (owned then ghost) P1 node numbering of DOLFINx and
    have shape (n_nodes, 3) or (n_nodes,); the first ``n_owned_nodes`` are owned.

    ``compiled`` (default): each step is two compiled calls (:mod:`fe_domain.compiled`, the
    operators in CSR; on several ranks their owned rows, with the ghost updates of v, π and p
    between the calls) instead of PETSc products and NumPy operations; the same arithmetic,
    to round-off. ``compiled=False``: PETSc's products, the reference.
    """

    def __init__(self, tagged_mesh: TaggedMesh, material: Material | Mapping[str, Material], *,
                 boundary_conditions: Sequence[Fixed | PrescribedVelocity] = (),
                 loads: Sequence[Traction | NormalPressure | BodyForce | GeostaticStress | UniformStress
                                 | Contraction] = (),
                 damping=None, formulation: str = "mixed",
                 alpha_tau: float = DEFAULT_ALPHA_TAU, safety_factor: float = 0.5,
                 dt: float | None = None, compiled: bool | None = None):
        if formulation not in ("mixed", "displacement"):
            raise ValueError(f"formulation = {formulation!r}: must be 'mixed' or 'displacement'")
        if not 0 < safety_factor <= 1:
            raise ValueError(f"safety_factor = {safety_factor!r}: must lie in (0, 1]")
        if formulation == "mixed" and not alpha_tau >= 0:
            raise ValueError(f"alpha_tau = {alpha_tau!r}: must be >= 0")
        self.tagged_mesh = tagged_mesh
        self.mesh = mesh = tagged_mesh.mesh
        self.comm = mesh.comm
        self.mixed = formulation == "mixed"
        self.damping = damping
        self.time = 0.0
        self.step_count = 0

        # Spaces: P1 vector (u, v, π), P1 scalar (p), DG0 (material fields, τ).
        self.V = fem.VectorFunctionSpace(mesh, ("CG", 1))
        self.Q = fem.FunctionSpace(mesh, ("CG", 1))
        self.D0 = fem.FunctionSpace(mesh, ("DG", 0))
        cell_nodes = self.Q.dofmap.list.array.reshape(-1, 4)
        if not np.array_equal(self.V.dofmap.list.array.reshape(-1, 4), cell_nodes):
            raise RuntimeError("P1 spaces do not share one node numbering")
        index_map = self.Q.dofmap.index_map
        self.n_owned_nodes = index_map.size_local
        self.n_nodes = index_map.size_local + index_map.num_ghosts

        self._boundary_nodes: dict[str, np.ndarray] = {}
        self._setup_geometry(cell_nodes)
        self._setup_material(material, alpha_tau)

        self.u, self.v, self.pi = (fem.Function(self.V, name=n) for n in ("u", "v", "pi"))
        self.p = fem.Function(self.Q, name="p")
        self.displacement = self.u.x.array.reshape(-1, 3)
        self.velocity = self.v.x.array.reshape(-1, 3)
        self.pressure = self.p.x.array
        self.projected_pressure_gradient = self.pi.x.array.reshape(-1, 3)
        #: External nodal forces (N), e.g. the DEM interface forces; persists until changed.
        #: On several ranks only the rows of owned nodes (< ``n_owned_nodes``) are read: each
        #: force is given once, by the rank that owns its node.
        self.external_force = np.zeros((self.n_nodes, 3))

        self.mass = np.repeat(self._lumped(forms.lumped_mass(ufl.TestFunction(self.Q), self.inertial_rho)), 3)
        self._inverse_mass = 1.0 / self.mass.reshape(-1, 3)
        cp = np.sqrt((self._K_cells + 4.0 * self._G_cells / 3.0) / self._inertial_rho_cells)
        self.dt_critical = self.comm.allreduce(float(np.min(self.h_cells / cp)), op=MPI.MIN)
        w, du = ufl.TestFunction(self.V), ufl.TrialFunction(self.V)
        q, dp = ufl.TestFunction(self.Q), ufl.TrialFunction(self.Q)
        self._f_int, self._f_int_petsc = self._vector(3)
        if self.mixed:
            self.pressure_mass = self._lumped(forms.lumped_pressure_mass(q, self.K))
            self.projection_mass = self._lumped(forms.lumped_projection_mass(q, self.tau))
            self._inverse_pressure_mass = 1.0 / self.pressure_mass
            with np.errstate(divide="ignore"):
                self._inverse_projection_mass = np.where(self.projection_mass > 0, 1.0 / self.projection_mass, 0.0)
            self._stiffness = self._matrix(forms.deviatoric_stiffness(w, du, self.G), "baij")
            self._divergence = self._matrix(forms.pressure_divergence(w, dp))
            self._projection = self._matrix(forms.pressure_gradient_projection(w, dp, self.tau))
            self._laplacian = self._matrix(forms.pressure_laplacian(q, dp, self.tau))
            self._projected, self._projected_petsc = self._vector(3)      # P p
            self._volumetric, self._volumetric_petsc = self._vector(1)    # ∫ q div v
            self._stabilisation, self._stabilisation_petsc = self._vector(1)   # ∫ τ ∇q·(∇p + π)
            self._pressure_change = np.zeros(self.n_owned_nodes)
            self._strain_energy = fem.form(forms.deviatoric_strain_energy(self.u, self.G))
        else:
            self._stiffness = self._matrix(forms.displacement_stiffness(w, du, self.G, self.K), "baij")
            self._strain_energy = fem.form(forms.deviatoric_strain_energy(self.u, self.G)
                                           + forms.volumetric_strain_energy(self.u, self.K))
        self._external_vector = dolfinx.la.vector(index_map, 3)
        self.dt = safety_factor * self.dt_critical if dt is None else dt

        self._setup_boundary_conditions(boundary_conditions)
        self._setup_loads(loads)

        # Energy bookkeeping (local sums over owned nodes; reduced when recorded).
        #: Record energies every ``energy_interval`` steps (0: never) into ``energy_history``.
        self.energy_interval = 0
        self.energy_history: list[dict] = []
        #: compiled.WORK_*: external work, damping work, stabilisation dissipation (this rank's sums)
        self._work = np.zeros(3)
        #: f_ext − f_int − f_damp of the last step (N per node).
        self.net_force = np.zeros((self.n_nodes, 3))
        self._damping_force = np.zeros((self.n_nodes, 3))
        self._velocity_change = np.zeros((self.n_nodes, 3))
        self._velocity_old = np.zeros((self.n_nodes, 3))
        self._increment = np.zeros((self.n_nodes, 3))
        self._kernel = self._compiled_step() if compiled is None or compiled else None

    @property
    def dt(self) -> float:
        """Time step Δt (s); settable (e.g. by a coupling that subcycles)."""
        return self._dt

    @dt.setter
    def dt(self, value: float) -> None:
        if not 0 < value <= self.dt_critical:
            raise ValueError(f"dt = {value!r}: must lie in (0, dt_critical = {self.dt_critical:.4g}] s")
        self._dt = float(value)

    # ------------------------------------------------------------------ setup
    def _setup_geometry(self, cell_nodes):
        """Node coordinates, vertex→node map and the element size h_e (smallest altitude)."""
        mesh = self.mesh
        tdim = mesh.topology.dim
        geometry_nodes = mesh.geometry.dofmap.array.reshape(-1, 4)
        self.node_coordinates = np.empty((self.n_nodes, 3))
        self.node_coordinates[cell_nodes] = mesh.geometry.x[geometry_nodes]
        self.input_node_index = np.empty(self.n_nodes, dtype=np.int64)
        self.input_node_index[cell_nodes] = np.asarray(mesh.geometry.input_global_indices)[geometry_nodes]
        self.global_node_index = np.asarray(
            self.Q.dofmap.index_map.local_to_global(np.arange(self.n_nodes, dtype=np.int32)))
        mesh.topology.create_connectivity(tdim, 0)
        mesh.topology.create_connectivity(tdim - 1, 0)
        mesh.topology.create_connectivity(tdim - 1, tdim)
        cell_vertices = mesh.topology.connectivity(tdim, 0).array.reshape(-1, 4)
        self._node_of_vertex = np.empty(mesh.topology.index_map(0).size_local
                                        + mesh.topology.index_map(0).num_ghosts, dtype=np.int32)
        self._node_of_vertex[cell_vertices] = cell_nodes

        x = self.node_coordinates[cell_nodes]                      # (cells, 4, 3)
        edges = x[:, 1:] - x[:, :1]
        volume = np.abs(np.einsum("ij,ij->i", edges[:, 0], np.cross(edges[:, 1], edges[:, 2]))) / 6.0
        faces = [(1, 2, 3), (0, 2, 3), (0, 1, 3), (0, 1, 2)]
        face_area = np.stack([0.5 * np.linalg.norm(np.cross(x[:, b] - x[:, a], x[:, c] - x[:, a]), axis=1)
                              for a, b, c in faces], axis=1)
        self.h_cells = 3.0 * volume / face_area.max(axis=1)
        #: volume of each local cell (m³)
        self.cell_volumes = volume

    def _setup_material(self, material, alpha_tau):
        """DG0 fields G, K, ρ (the weight's density) and Sρ (the inertia's: the material's inertia
        scale S times ρ) from one Material or a {cell group name: Material} map; τ_e."""
        n_cells = len(self.h_cells)
        materials = {None: material} if isinstance(material, Material) else dict(material)
        G, K, rho, inertial = (np.full(n_cells, np.nan) for _ in range(4))
        for name, mat in materials.items():
            cells = slice(None) if name is None else self.tagged_mesh.cells(name)
            G[cells], K[cells], rho[cells] = mat.shear_modulus, mat.bulk_modulus, mat.rho
            inertial[cells] = mat.inertia_scale * mat.rho
        if np.isnan(G).any():
            missing = sorted(set(self.tagged_mesh.names(3)) - set(materials))
            raise ValueError(f"material: cells without a material; cell groups not given: {missing}")
        self._G_cells, self._K_cells, self._inertial_rho_cells = G, K, inertial
        self.alpha_tau = alpha_tau if self.mixed else 0.0
        tau = self.alpha_tau * self.h_cells ** 2 / (2.0 * G)
        cell_dofs = self.D0.dofmap.list.array
        self.G, self.K, self.rho, self.inertial_rho, self.tau = (
            fem.Function(self.D0, name=n) for n in ("G", "K", "rho", "inertial_rho", "tau"))
        for fn, values in ((self.G, G), (self.K, K), (self.rho, rho), (self.inertial_rho, inertial), (self.tau, tau)):
            fn.x.array[cell_dofs] = values

    def _setup_boundary_conditions(self, conditions):
        fixed, prescribed = [], []
        for bc in conditions:
            nodes = self.boundary_nodes(bc.boundary)
            if isinstance(bc, Fixed):
                fixed.extend(3 * nodes + c for c in bc.components)
            elif isinstance(bc, PrescribedVelocity):
                comps = [c for c, value in enumerate(bc.velocity) if value is not None]
                values = np.array([bc.velocity[c] for c in comps], dtype=float)
                prescribed.append((np.concatenate([3 * nodes + c for c in comps]),
                                   np.repeat(values, len(nodes)), bc.amplitude))
            else:
                raise TypeError(f"boundary condition {bc!r}: not Fixed or PrescribedVelocity")
        self._fixed_dofs = np.unique(np.concatenate(fixed)).astype(np.int64) if fixed else np.empty(0, np.int64)
        self._prescribed = prescribed

    def _setup_loads(self, loads):
        """Assemble each load once into a nodal vector; f_ext(t) = Σ amplitude_i(t) F_i. A
        geostatic stress or a contraction is an initial stress σ0_k, its load −∫ σ0_k : ∇w;
        ``initial_stress`` is their sum at the solver's time (a UFL tensor, brought up to date
        by :meth:`update_initial_stress`; None without)."""
        w = ufl.TestFunction(self.V)
        ds = ufl.Measure("ds", domain=self.mesh, subdomain_data=self.tagged_mesh.facet_tags)
        self._loads, forms_, self._stress_amplitudes = [], [], []
        terms = []
        for load in loads:
            if isinstance(load, (GeostaticStress, UniformStress, Contraction)):
                stress, amplitude = self._initial_stress_term(load), getattr(load, "amplitude", constant)
                forms_.append((forms.initial_stress_load(w, stress), amplitude))
                scale = fem.Constant(self.mesh, PETSc.ScalarType(amplitude(self.time)))
                self._stress_amplitudes.append((scale, amplitude))
                terms.append(scale * stress)
                continue
            if isinstance(load, BodyForce):
                form = forms.body_force_load(w, self.rho, self._constant(load.acceleration))
            elif isinstance(load, Traction):
                tag = self.tagged_mesh.tag(load.boundary, 2)
                form = forms.traction_load(w, self._constant(load.traction), ds(tag))
            elif isinstance(load, NormalPressure):
                tag = self.tagged_mesh.tag(load.boundary, 2)
                form = forms.normal_pressure_load(w, self._constant(load.pressure), ds(tag),
                                                  ufl.FacetNormal(self.mesh))
            else:
                raise TypeError(f"load {load!r}: not Traction, NormalPressure, BodyForce, GeostaticStress, "
                                "UniformStress or Contraction")
            forms_.append((form, load.amplitude))
        self.initial_stress = sum(terms[1:], terms[0]) if terms else None
        for form, amplitude in forms_:
            vector = dolfinx.la.vector(self.V.dofmap.index_map, 3)
            self._assemble(vector, fem.form(form))
            self._loads.append((vector.array.reshape(-1, 3).copy(), amplitude))

    def _initial_stress_term(self, load):
        """σ0 of one geostatic, uniform or contraction stress (:mod:`fe_domain.forms`) on its groups' cells."""
        indicator = fem.Function(self.D0)
        for group in load.groups:
            indicator.x.array[self.D0.dofmap.list.array[self.tagged_mesh.cells(group)]] = 1.0
        if isinstance(load, UniformStress):
            return indicator * ufl.as_matrix(np.asarray(load.stress, dtype=float).tolist())
        if isinstance(load, Contraction):
            axis = np.asarray(load.axis, dtype=float) / np.linalg.norm(load.axis)
            return forms.contraction_stress(indicator, self.G, self.K, self._constant(axis),
                                            self._constant(load.strain))
        return forms.geostatic_stress(ufl.SpatialCoordinate(self.mesh), indicator, self.rho,
                                      self._constant(load.acceleration), self._constant(load.ground),
                                      self._constant(load.K0))

    def load_vector(self, time: float) -> np.ndarray:
        """The assembled loads at ``time``, Σ amplitude_i(time) F_i (n_nodes, 3) (without
        ``external_force``): e.g. the right-hand side of a static solve with ``operators()``."""
        total = np.zeros((self.n_nodes, 3))
        for vector, amplitude in self._loads:
            total += amplitude(time) * vector
        return total

    @property
    def pressure_form(self):
        """The mean stress measured from the initial stress, as a UFL expression: the mixed
        formulation's p, the displacement formulation's K div u."""
        return self.p if self.mixed else self.K * ufl.div(self.u)

    @property
    def fixed_dofs(self) -> np.ndarray:
        """The local dof numbers (3 × node + component) held at zero velocity."""
        return self._fixed_dofs

    def update_initial_stress(self) -> None:
        """Set ``initial_stress``'s amplitudes to the solver's time (before evaluating it)."""
        for scale, amplitude in self._stress_amplitudes:
            scale.value = amplitude(self.time)

    def _constant(self, value):
        return fem.Constant(self.mesh, PETSc.ScalarType(value) if np.ndim(value) == 0
                            else np.asarray(value, dtype=PETSc.ScalarType))

    def _lumped(self, integrand) -> np.ndarray:
        vector = dolfinx.la.vector(self.Q.dofmap.index_map, 1)
        self._assemble(vector, fem.form(integrand))
        return vector.array.copy()

    @staticmethod
    def _assemble(vector, form):
        """Assemble ``form`` into a preallocated la.Vector, then ghost updates (reverse add, forward)."""
        vector.array[:] = 0.0
        fem.assemble_vector(vector.array, form)
        vector.scatter_reverse(ScatterMode.add)
        vector.scatter_forward()

    def _matrix(self, bilinear_form, mat_type=None) -> PETSc.Mat:
        """Assemble a bilinear form once into a finalised PETSc matrix (owned rows complete)."""
        form = fem.form(bilinear_form)
        matrix = dolfinx.fem.petsc.create_matrix(form, mat_type)
        dolfinx.fem.petsc.assemble_matrix(matrix, form)
        matrix.assemble()
        return matrix

    def _vector(self, bs):
        """A nodal la.Vector with ``bs`` components and a PETSc Vec sharing its memory."""
        vector = dolfinx.la.vector(self.Q.dofmap.index_map, bs)
        return vector, dolfinx.cpp.la.petsc.create_vector_wrap(vector)

    def refine_critical_step(self, tolerance: float = 1e-9, max_iterations: int = 3000) -> float:
        """Replace the cell estimate of :attr:`dt_critical` by the step's own limit and return it
        (displacement formulation; collective). The lumped-mass central-difference step is stable
        for Δt ≤ 2/ω_max (Belytschko, Liu & Moran, *Nonlinear Finite Elements*, 2000, §6.3), ω_max²
        the largest eigenvalue of M⁻¹K. It is found by power iteration on the symmetric
        M^-½ K M^-½ with its Rayleigh quotient, which rises to ω_max² from below, until it changes
        by less than ``tolerance`` (relative); the time step's safety factor covers what is left.
        The supports are not imposed (the unconstrained K has the larger ω_max: on the safe side),
        the start vector is a function of the node coordinates (any partition starts alike).
        The cell estimate min h_e/c_p can lie on either side of 2/ω_max (a lone sliver's limit is
        half its estimate; the tunnel's mesh allows 1.28× its estimate)."""
        if self.mixed:
            raise ValueError("refine_critical_step: the exact limit is the displacement formulation's; the mixed "
                             "form's explicit pressure update has its own (module docstring)")
        stiffness = self._stiffness
        x, y, scaled = stiffness.createVecRight(), stiffness.createVecLeft(), stiffness.createVecRight()
        owned = self.node_coordinates[:self.n_owned_nodes]
        x.array[:] = np.cos(owned @ np.array([[1.0e3, 7.3e3, 3.1e3], [5.7e3, 2.3e3, 8.9e3], [4.1e3, 6.7e3, 1.9e3]])
                            + np.array([0.3, 1.1, 2.9])).ravel()
        x.normalize()
        inverse_root_mass = 1.0 / np.sqrt(self.mass[:3 * self.n_owned_nodes])
        rayleigh = 0.0
        for _ in range(max_iterations):
            scaled.array[:] = x.array * inverse_root_mass
            stiffness.mult(scaled, y)
            y.array[:] *= inverse_root_mass
            previous, rayleigh = rayleigh, y.dot(x)
            y.copy(x)
            x.normalize()
            if abs(rayleigh - previous) <= tolerance * rayleigh:
                break
        self.dt_critical = 2.0 / float(np.sqrt(rayleigh))
        return self.dt_critical

    def operators(self) -> dict[str, PETSc.Mat]:
        """The assembled step operators by name (K_dev or K, and Bᵀ, P, L for the mixed form)."""
        if not self.mixed:
            return {"K": self._stiffness}
        return {"K_dev": self._stiffness, "B^T": self._divergence, "P": self._projection, "L": self._laplacian}

    def operator_bytes(self) -> int:
        """This rank's storage (bytes) of the step operators: values, column and row indices."""
        index_size, value_size = np.dtype(PETSc.IntType).itemsize, np.dtype(PETSc.ScalarType).itemsize
        parts = 1 if self.comm.size == 1 else 2            # MPI: diagonal and off-diagonal blocks
        total = 0
        for matrix in self.operators().values():
            entries = int(matrix.getInfo(PETSc.Mat.InfoType.LOCAL)["nz_used"])
            bs = matrix.getBlockSize() if "baij" in matrix.getType() else 1
            rows = matrix.getLocalSize()[0] // bs
            total += entries * value_size + (entries // bs ** 2 + parts * (rows + 1)) * index_size
        return total

    def compiled_operator_bytes(self) -> int:
        """Storage (bytes) of the compiled step's copy of the operators (one rank; 0 without):
        the same values as PETSc's, one column index per node pair instead of one per scalar
        entry (:class:`fe_domain.compiled.StepOperators`). Held besides PETSc's matrices."""
        return sum(array.nbytes for array in self._kernel[0]) if self._kernel is not None else 0

    def _compiled_step(self):
        """The operators on their node adjacency and the nodal arrays (this solid's memory) for
        :mod:`fe_domain.compiled`."""
        n = self.n_nodes
        local = functools.partial(compiled.scipy_matrix, index_map=self.Q.dofmap.index_map)
        if self.mixed:
            operators = [self._stiffness, self._divergence, self._projection, self._laplacian]
            if self.comm.size > 1:  # owned rows only: the transposes' own rows for B v and Pᵀ π
                operators += [m.transpose(PETSc.Mat()) for m in (self._divergence, self._projection)]
            ops = compiled.step_operators(self.n_owned_nodes, n, *map(local, operators))
            scalars = (self._volumetric.array, self._stabilisation.array,
                       self._inverse_pressure_mass, self._inverse_projection_mass)
        else:
            ops = compiled.step_operators(self.n_owned_nodes, n, local(self._stiffness))
            scalars = (np.zeros(n), np.zeros(n), np.zeros(n), np.zeros(n))
        external = self.external_force.reshape(-1)  # the kernels read the owned rows only
        volumetric, stabilisation, inverse_pressure_mass, inverse_projection_mass = scalars
        groups = [np.full(len(dofs), g, np.int64) for g, (dofs, _, _) in enumerate(self._prescribed)]
        flat = lambda parts, dtype: np.concatenate(parts).astype(dtype) if parts else np.zeros(0, dtype)  # noqa: E731
        nodal = compiled.NodalArrays(
            displacement=self.u.x.array, velocity=self.v.x.array, pressure=self.p.x.array,
            projected_gradient=self.pi.x.array, external_force=external,
            loads=np.array([vector.reshape(-1) for vector, _ in self._loads]).reshape(len(self._loads), 3 * n),
            f_ext=np.zeros(3 * n), f_int=self._f_int.array, net_force=self.net_force.reshape(-1),
            damping_force=self._damping_force.reshape(-1), velocity_old=self._velocity_old.reshape(-1),
            velocity_change=self._velocity_change.reshape(-1), increment=self._increment.reshape(-1),
            mass=self.mass, inverse_mass=self._inverse_mass.reshape(-1), inverse_pressure_mass=inverse_pressure_mass,
            inverse_projection_mass=inverse_projection_mass,
            projected=self._projected.array if self.mixed else np.zeros(3 * n),
            volumetric=volumetric, stabilisation=stabilisation, fixed_dofs=self._fixed_dofs,
            prescribed_dofs=flat([dofs for dofs, _, _ in self._prescribed], np.int64),
            prescribed_values=flat([values for _, values, _ in self._prescribed], np.float64),
            prescribed_group=flat(groups, np.int64), work=self._work)
        # one step's amplitudes, and row views of them kept for CachedEntry (the same objects each step)
        self._step_amplitudes = (np.zeros((1, len(self._loads))), np.zeros((1, len(self._prescribed))))
        self._step_amplitude_rows = tuple(a[0] for a in self._step_amplitudes)
        self._velocity_update = CachedEntry(compiled.velocity_update)
        self._displacement_update = CachedEntry(compiled.displacement_update)
        return ops, nodal

    def compiled_arguments(self):
        """(settings, operators, nodal arrays) of the compiled step (:mod:`fe_domain.compiled`)
        for callers that make whole steps in one compiled call, or None: the solid steps with
        PETSc, or on several ranks (their steps update ghosts between the calls, :meth:`step`)."""
        return self._step_arguments() if self.comm.size == 1 else None

    def _step_arguments(self):
        if self._kernel is None:
            return None
        ops, nodal = self._kernel
        kind = {MassProportionalDamping: compiled.DAMPING_MASS_PROPORTIONAL,
                LocalNonViscousDamping: compiled.DAMPING_LOCAL}.get(type(self.damping), compiled.DAMPING_NONE)
        if self.damping is not None and kind == compiled.DAMPING_NONE:
            raise TypeError(f"damping {self.damping!r}: the compiled step knows mass-proportional and local damping")
        alpha = float(self.damping.alpha) if self.damping is not None else 0.0
        return compiled.StepSettings(self.dt, self.mixed, kind, alpha), ops, nodal

    # ------------------------------------------------------------------ stepping
    def step(self) -> None:
        """Advance one time step, docs/design.md §4.4, steps 1–4 (step 4 at the start of the next step)."""
        if self._kernel is not None:
            settings, ops, nodal = self._step_arguments()
            several = self.comm.size > 1
            self.compiled_amplitudes(1, *self._step_amplitudes)
            self._velocity_update(settings, ops, nodal, *self._step_amplitude_rows)
            if several:
                self.v.x.scatter_forward()
                if self.mixed:
                    self.pi.x.scatter_forward()
            if self.energy_due():
                self._record_energies(self._velocity_old)
            self._displacement_update(settings, ops, nodal)
            if several and self.mixed:
                self.p.x.scatter_forward()
            self.time += self.dt
            self.step_count += 1
            return
        dt = self.dt
        # Step 1 (and step 4 for p^n): f_int = K_dev u^n + Bᵀ p^n, π^n = −G̃⁻¹ P p^n.
        self._stiffness.mult(self.u.vector, self._f_int_petsc)
        if self.mixed:
            self._divergence.multAdd(self.p.vector, self._f_int_petsc, self._f_int_petsc)
            self._projection.mult(self.p.vector, self._projected_petsc)
            self._projected.scatter_forward()
            np.multiply(self._projected.array.reshape(-1, 3), -self._inverse_projection_mass[:, None],
                        out=self.projected_pressure_gradient)
        self._f_int.scatter_forward()
        self._external_vector.array[:] = self.external_force.ravel()
        self._external_vector.scatter_forward()  # the owners' forces on the ghosts
        f_ext = self._external_vector.array.reshape(-1, 3)
        for vector, amplitude in self._loads:
            f_ext += amplitude(self.time) * vector
        np.subtract(f_ext, self._f_int.array.reshape(-1, 3), out=self.net_force)
        velocity = self.velocity
        f_damp = self._damping_force
        if self.damping is not None:
            f_damp[:] = self.damping.force(self.net_force, velocity, self.mass.reshape(-1, 3))
            self.net_force -= f_damp
        velocity_old = self._velocity_old
        velocity_old[:] = velocity
        velocity += dt * self._inverse_mass * self.net_force
        flat = self.v.x.array
        flat[self._fixed_dofs] = 0.0
        t_half = self.time + 0.5 * dt
        for dofs, values, amplitude in self._prescribed:
            flat[dofs] = amplitude(t_half) * values
        np.subtract(velocity, velocity_old, out=self._velocity_change)
        if self.energy_due():
            self._record_energies(velocity_old)
        # Step 2.
        increment = np.multiply(dt, velocity, out=self._increment)
        owned = slice(0, self.n_owned_nodes)
        self._work[compiled.WORK_EXTERNAL] += _dot(f_ext[owned], increment[owned])
        if self.damping is not None:
            self._work[compiled.WORK_DAMPING] += _dot(f_damp[owned], increment[owned])
        self.displacement += increment
        # Step 3: Δp = M_p⁻¹ [Δt (Bᵀ)ᵀ v^{n+½} − (L p^n + Pᵀ π^n)] on owned nodes, then p's ghosts.
        if self.mixed:
            self._divergence.multTranspose(self.v.vector, self._volumetric_petsc)
            self._laplacian.mult(self.p.vector, self._stabilisation_petsc)
            self._projection.multTransposeAdd(self.pi.vector, self._stabilisation_petsc,
                                              self._stabilisation_petsc)
            stabilisation = self._stabilisation.array[owned]
            pressure_change = self._pressure_change
            np.multiply(dt, self._volumetric.array[owned], out=pressure_change)
            pressure_change -= stabilisation
            pressure_change *= self._inverse_pressure_mass[owned]
            pressure = self.pressure[owned]
            self._work[compiled.WORK_STABILISATION] += _dot(pressure + 0.5 * pressure_change, stabilisation)
            pressure += pressure_change
            self.p.x.scatter_forward()
        self.time += dt
        self.step_count += 1

    def run(self, n_steps: int, callback=None) -> None:
        """``n_steps`` steps; ``callback(solver)`` after each (outputs, coupling). Without a
        callback, a compiled solid runs the steps between energy records in one call."""
        done = 0
        while done < n_steps:
            if callback is None and self.compiled_arguments() is not None and not self.energy_due():
                count = n_steps - done
                if self.energy_interval > 0:
                    count = min(count, self.energy_interval - self.step_count % self.energy_interval)
                self.advance_compiled(count)
                done += count
                continue
            self.step()
            done += 1
            if callback is not None:
                callback(self)

    def step_times(self, count):
        """tⁿ of the next ``count`` steps, added up as :meth:`step` adds them."""
        times, t = [], self.time
        for _ in range(count):
            times.append(t)
            t += self.dt
        return times

    def compiled_amplitudes(self, count, loads=None, prescribed=None):
        """(load amplitudes at tⁿ, prescribed-velocity amplitudes at t^{n+½}) of the next
        ``count`` steps, one row a step (into the first rows of ``loads`` and ``prescribed``,
        if given)."""
        times = self.step_times(count)
        if loads is None:
            loads, prescribed = np.empty((count, len(self._loads))), np.empty((count, len(self._prescribed)))
        for m, (_, amplitude) in enumerate(self._loads):
            loads[:count, m] = [amplitude(t) for t in times]
        for m, (_, _, amplitude) in enumerate(self._prescribed):
            prescribed[:count, m] = [amplitude(t + 0.5 * self.dt) for t in times]
        return loads, prescribed

    def advance_compiled(self, count):
        """``count`` steps in one compiled call (no energy record due among them)."""
        compiled.steps(*self.compiled_arguments(), *self.compiled_amplitudes(count))
        self.finish_compiled_steps(count)

    def finish_compiled_steps(self, count):
        """The clock after ``count`` steps made by compiled code."""
        for _ in range(count):
            self.time += self.dt
        self.step_count += count

    # ------------------------------------------------------------------ checkpoints
    _NODE_FIELDS = ("displacement", "velocity", "pressure", "velocity_change")

    def checkpoint_state(self) -> dict:
        """This rank's state (u, v, p, clock, energy accumulators) as arrays, for ``np.savez``,
        with the mesh-input index of each local node (owned first), so that a run on another
        partition or rank count can find its nodes (:meth:`restore_from_ranks`).

        π needs no saving: step 1 recomputes it from p.
        """
        return {"displacement": self.displacement.copy(), "velocity": self.velocity.copy(),
                "pressure": self.pressure.copy(), "velocity_change": self._velocity_change.copy(),
                "clock": np.array([self.time, self.step_count, self.dt]),
                "energy_accumulators": self._work.copy(),
                "input_node_index": self.input_node_index.copy(), "n_owned_nodes": np.int64(self.n_owned_nodes)}

    def fits(self, state) -> bool:
        """Whether ``state`` was written by this very partition (the same local nodes, in order)."""
        if "input_node_index" not in state:
            return state["displacement"].shape == self.displacement.shape
        return np.array_equal(state["input_node_index"], self.input_node_index)

    def restore_state(self, state) -> None:
        """Inverse of :meth:`checkpoint_state`, on the partition that wrote it (:meth:`fits`)."""
        if not self.fits(state):
            raise ValueError("checkpoint was written for another mesh partition or rank count")
        self.displacement[:] = state["displacement"]
        self.velocity[:] = state["velocity"]
        self.pressure[:] = state["pressure"]
        self._velocity_change[:] = state["velocity_change"]
        self._restore_clock(state)
        self._work[:] = state["energy_accumulators"]

    def restore_from_ranks(self, states) -> None:
        """The state written by every rank of another partition (any rank count) of the same
        mesh: each local node (owned and ghost) takes the values of the node with its mesh-input
        index, from the rank that owned it. Nodal values are exact; the energy accumulators
        (sums over each rank's owned nodes) go to rank 0 as their total, so the global sums
        agree to round-off."""
        keys = np.concatenate([st["input_node_index"][:int(st["n_owned_nodes"])] for st in states])
        order = np.argsort(keys)
        rows = np.searchsorted(keys, self.input_node_index, sorter=order)
        rows = order[np.minimum(rows, len(keys) - 1)]
        if not np.array_equal(keys[rows], self.input_node_index):
            raise ValueError("checkpoint was written for another mesh")
        for name, target in zip(self._NODE_FIELDS, (self.displacement, self.velocity, self.pressure,
                                                    self._velocity_change), strict=True):
            owned = [st[name][:int(st["n_owned_nodes"])] for st in states]
            target[:] = np.concatenate(owned)[rows]
        self._restore_clock(states[0])
        totals = np.sum([st["energy_accumulators"] for st in states], axis=0) if self.comm.rank == 0 else np.zeros(3)
        self._work[:] = totals

    def _restore_clock(self, state):
        self.time, step_count, self.dt = state["clock"]
        self.step_count = int(step_count)

    # ------------------------------------------------------------------ energies
    def energy_due(self) -> bool:
        return self.energy_interval > 0 and self.step_count % self.energy_interval == 0

    def _record_energies(self, velocity_old):
        """Energies at t^n, appended to ``energy_history``.

        kinetic ½ Σ M |v^n|², v^n = (v^{n−½} + v^{n+½})/2; strain ∫ G dev ε:dev ε + ½ Σ M_p p²
        (mixed) or + ∫ K/2 (div u)² (displacement); external and damping work Σ f·Δu;
        stabilisation: the pressure energy removed by step 3's τ-term, Σ p^{n+½}·∫τ∇q·(∇p+π).
        total = kinetic + strain − external_work + damping_work + stabilisation (constant).
        """
        owned = slice(0, self.n_owned_nodes)
        v_n = 0.5 * (velocity_old[owned] + self.velocity[owned])
        kinetic = 0.5 * float(np.sum(self.mass.reshape(-1, 3)[owned] * v_n ** 2))
        strain = fem.assemble_scalar(self._strain_energy)
        if self.mixed:
            strain += 0.5 * float(np.sum(self.pressure_mass[owned] * self.pressure[owned] ** 2))
        local = np.array([kinetic, strain, *self._work])
        kinetic, strain, external, damping, stabilisation = self.comm.allreduce(local, op=MPI.SUM)
        self.energy_history.append({"time": self.time, "step": self.step_count, "kinetic": kinetic,
                                    "strain": strain, "external_work": external,
                                    "damping_work": damping, "stabilisation": stabilisation,
                                    "total": kinetic + strain - external + damping + stabilisation})

    # ------------------------------------------------------------------ boundaries
    def boundary_nodes(self, name: str) -> np.ndarray:
        """Local node indices (owned and ghost) on the facets of group ``name``.

        Collective on first use of a name (ranks exchange shared nodes); cached after.
        """
        if name not in self._boundary_nodes:
            facets = self.tagged_mesh.facets(name)
            self._boundary_nodes[name] = fem.locate_dofs_topological(
                self.Q, self.mesh.topology.dim - 1, facets).astype(np.int64)
        return self._boundary_nodes[name]

    def facet_triangles(self, name: str) -> np.ndarray:
        """(n_facets, 3) local node indices of the facets of group ``name`` owned by this rank.

        Each facet is reported by exactly one rank; vertex positions are
        ``node_coordinates + displacement`` at those indices.
        """
        tdim = self.mesh.topology.dim
        facets = self.tagged_mesh.facets(name)
        facets = facets[facets < self.mesh.topology.index_map(tdim - 1).size_local]
        facet_vertices = self.mesh.topology.connectivity(tdim - 1, 0).array.reshape(-1, 3)
        return self._node_of_vertex[facet_vertices[facets]]

    def reaction(self, name: str) -> np.ndarray:
        """Total force (N) the supports of group ``name`` exert on the body, at the last step (collective).

        R = M a − (f_ext − f_int − f_damp) summed over the group's owned nodes.
        """
        nodes = self.boundary_nodes(name)
        nodes = nodes[nodes < self.n_owned_nodes]
        inertia = self.mass.reshape(-1, 3)[nodes] * self._velocity_change[nodes] / self.dt
        local = np.sum(inertia - self.net_force[nodes], axis=0)
        return self.comm.allreduce(local, op=MPI.SUM)
