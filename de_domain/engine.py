"""The DEM step sequence (docs/design.md §2.12; YADE-style visible engine list).

One step is, in order (:mod:`de_domain.fused` runs 3–7 for many steps in one
compiled loop with two parallel regions per step; 1–2 happen in Python when a run
starts or the lists must be rebuilt):

1. boundary bookkeeping   – walls/facets moved from outside since the last step
2. neighbour update       – Verlet lists rebuilt when displacements exceed the skin
3. sphere–sphere contacts – per-pair forces, then per-particle sums (resets forces)
4. walls and facets       – plane walls, triangle facets, vertex force/impulse split
5. gravity, damping, leapfrog integration of owned particles
6. energy record          – terms at time tⁿ, increments accumulated
7. boundaries advance     – x_wall += v_wall Δt, facet vertices += v Δt
"""
from __future__ import annotations

import dataclasses
import math
from collections import namedtuple

import numpy as np

from numba_support.dispatch import CachedEntry

from . import fused
from .clumps import Clumps
from .contact_laws import HERTZ, LAWS
from .materials import PAIR_ROLLING_STIFFNESS, Material, material_arrays, pair_table
from .neighbors import ContactRecords, NeighborList
from .particles import ARRAY_FIELDS, Particles
from .runs import SerialRun
from .state import (
    BOOK_ACCUMULATED,
    BOOK_FIRST,
    BOOK_INITIAL_TOTAL,
    BOOK_INITIALISED,
    BOOK_LAST,
    BOOK_STATE,
    CLOCK_PARTICLE_SHIFT,
    CLOCK_STEPS,
    CLOCK_TIME,
    MEMBER_COLUMNS,
    N_BOOKS,
    N_CLOCK,
    ClumpArrays,
    ContactParameters,
    FacetCandidates,
    FacetMeshes,
    PairList,
    ParticleArrays,
    PlaneWalls,
    StepSettings,
)
from .walls import FacetMesh, PlaneWall, vertex_forces_of_rows

SORTED_MIN_STEPS = 8  # runs this long (every run, with Engine.keep_sorted) use spatially sorted copies
STATE_TERMS = ("kinetic_translational", "kinetic_rotational", "gravity",
               "elastic_normal", "elastic_tangential", "elastic_rolling")
RATE_TERMS = ("work_walls", "work_boundary", "friction", "contact_damping", "background_damping")
DISSIPATION_TERMS = ("friction", "contact_damping", "background_damping")
WORK_TERMS = ("work_walls", "work_boundary")

Boundaries = namedtuple("Boundaries", ["walls", "facets"])
"""Where the boundaries are when a run starts (:meth:`Engine.boundaries`): ``walls`` = (point,
normal, velocity, material) arrays of the plane walls, ``facets`` = (vertices, vertex
velocities) of all facet meshes concatenated. A run advances these arrays in place."""


def _distributed():
    """de_domain.distributed, imported on first use (it imports mpi4py, which starts MPI)."""
    from . import distributed

    return distributed


class Engine:
    """Spheres + plane walls + facet meshes, advanced by :meth:`step` (see module docstring).

    ``dt=None`` takes ``safety_factor × critical_timestep()``. ``skin`` defaults to
    0.2 × the mean radius. ``local_damping`` α_b and ``viscous_damping`` α_v [1/s]
    are the background damping of docs/design.md §2.13.

    ``comm`` (an mpi4py communicator): the particles are spread over its ranks
    (:mod:`de_domain.distributed`; every rank passes the same global ``particles``,
    walls and facets). ``particles`` then holds this rank's owned particles and
    ghosts in ascending global id (``domain.ids``); :meth:`global_particles` gathers
    them. Results are bit-identical for any number of ranks.

    The steps are taken by the engine's run object, ``runner`` (:mod:`de_domain.runs`: a
    :class:`~de_domain.runs.SerialRun`, or a :class:`~de_domain.distributed.DistributedRun`
    with ``comm``), through the public step interface below (:meth:`boundaries` …
    :meth:`install_rows`); every operation that needs other ranks goes through it too, so
    the engine itself makes no MPI call.

    ``keep_sorted`` (default False): runs leave the particle state in the engine's
    spatially sorted copies instead of writing it back to ``particles`` after every
    run, so that a caller who runs many short windows (the FE–DE coupling: one per FE
    step) pays neither the gather nor the scatter of the copies each time. Reading
    :attr:`particles` or :attr:`acceleration` writes the state back first (and the
    next run gathers it again), so what a caller reads is always current; a reference
    to the arrays kept from before a run is not.
    """

    def __init__(self, particles: Particles, materials, walls=(), facets=(), contact_law="linear",
                 gravity=(0.0, 0.0, -9.81), dt=None, safety_factor=0.3, local_damping=0.0,
                 viscous_damping=0.0, skin=None, comm=None, clumps=None):
        if contact_law not in LAWS:
            raise ValueError(f"Engine: contact_law = {contact_law!r}; allowed: {sorted(LAWS)}")
        if not 0.0 < safety_factor <= 1.0:
            raise ValueError(f"Engine: safety_factor = {safety_factor!r} is outside (0, 1]")
        if not 0.0 <= local_damping < 1.0:
            raise ValueError(f"Engine: local_damping = {local_damping!r} is outside [0, 1)")
        if viscous_damping < 0.0:
            raise ValueError(f"Engine: viscous_damping = {viscous_damping!r} must be >= 0")
        self._copies_hold_state = False  # the sorted copies, not the public arrays, are current
        self.keep_sorted = False
        self.runner = SerialRun()
        self.domain = None  # de_domain.distributed.Domain with ``comm``
        #: distributed: gather the wall forces over the ranks after every run (False: only in
        #: update_wall_forces, checkpoints, and before a wall moved from outside is booked)
        self.wall_forces_each_run = True
        #: the walls' ``force`` is not the last step's (a run with ``wall_forces_each_run`` off)
        self.wall_forces_stale = False
        self.particles = particles
        if clumps is not None and clumps.member_of.size != particles.n:
            raise ValueError(f"Engine: the clumps are over {clumps.member_of.size} particles, the engine has "
                             f"{particles.n}")
        #: rigid clumps of member spheres (de_domain.clumps.Clumps; none by default): all of them, over
        #: the global particle ids, on every rank of a distributed engine (current after each run)
        self.clumps = clumps if clumps is not None else Clumps.none(particles.n)
        self.materials = [m if isinstance(m, Material) else Material(**m) for m in materials]
        n_mat = len(self.materials)
        used = [particles.material] + [np.array([w.material]) for w in walls] + \
               [np.array([f.material]) for f in facets]
        used = np.concatenate(used)
        if used.size and (used.min() < 0 or used.max() >= n_mat):
            raise ValueError(f"Engine: material ids must be in [0, {n_mat - 1}], got {sorted(set(used.tolist()))}")
        self.contact_law = contact_law
        self.law = LAWS[contact_law]
        self.pair_params = pair_table(self.materials)
        self.density, self.young, self.poisson = material_arrays(self.materials)
        self.walls = list(walls)
        self.facets = list(facets)
        # where the engine last left each wall and facet vertex: a move made from outside
        # between two runs is the difference (booked as boundary work)
        self._wall_points_known = np.array([w.point for w in self.walls]).reshape(-1, 3)
        self.gravity = np.array(gravity, dtype=np.float64).reshape(3)
        self.safety_factor = float(safety_factor)
        self.local_damping = float(local_damping)
        self.viscous_damping = float(viscous_damping)
        self.dt = float(dt) if dt is not None else self.safety_factor * self.critical_timestep()
        if not self.dt > 0.0:
            raise ValueError(f"Engine: dt = {self.dt!r} must be > 0")
        if skin is None:
            skin = 0.2 * float(np.mean(particles.radius)) if particles.n else 0.0
        self.neighbors = NeighborList(skin)
        self.neighbors.rolling = bool(np.any(self.pair_params[:, :, PAIR_ROLLING_STIFFNESS] > 0.0))
        self.time = 0.0
        self.step_count = 0
        self._setup_facet_topology()
        self._walls_state = None
        self._clock = np.zeros(N_CLOCK)
        self._clock[CLOCK_PARTICLE_SHIFT] = -1.0
        self._identity_perm = np.zeros(0, np.int32)  # perm of the sorted copies: 0, 1, ..., n − 1
        self._free_member_of = np.zeros(0, np.int32)  # −1 per particle: no clump
        self._sorted_clump_rows = None  # the clumps' member_of and member rows in the spatial order
        self._member_load = np.zeros((0, MEMBER_COLUMNS))  # ClumpArrays.member_load
        self._clump_share = None  # (active, booked) of ClumpArrays: set_clump_share; default all, all
        self._step_buffers = None  # fused.step_buffers of a distributed step with clumps
        self._forces_kernel = CachedEntry(fused.step_forces)
        self._collect_kernel = CachedEntry(fused.collect_member_loads)
        self._finish_kernel = CachedEntry(fused.finish_step)
        self._sorted = None  # buffers of the spatially sorted copies (_sorted_copies)
        self._advance_kernel = CachedEntry(fused.advance)  # fused.advance without per-call typing
        self._wall_totals = CachedEntry(fused.wall_totals)
        n = particles.n
        self.acceleration = np.zeros((n, 3))
        self._allocate_pair_arrays(0)
        self._energy_reset()
        self._pending_records = None  # contact history from a checkpoint, for the first list build
        if comm is not None:
            _distributed().distribute(self, particles, comm)

    @property
    def particles(self) -> Particles:
        """The particles (this rank's owned ones and ghosts, when distributed), current:
        written back from the sorted copies first if a ``keep_sorted`` run left the
        state there."""
        self.write_back()
        return self._particles

    @particles.setter
    def particles(self, value: Particles):
        self._copies_hold_state = False
        self._particles = value
        self._clump_rows = None  # made again for the new rows (clump_rows)

    def clump_rows(self):
        """(member_of, member_row) over this process's particle rows: the clump of each row
        (−1: a free sphere), and the row of each member of the clumps (template order; −1 where
        another rank owns it). A serial engine's are the clumps' own ``member_of`` and
        ``member_index``."""
        if self._clump_rows is None:
            c = self.clumps
            if self.domain is None:
                self._clump_rows = (c.member_of, c.member_index)
            else:
                ids = self.domain.ids
                member_of = c.member_of[ids]
                slot = np.full(c.member_of.size, -1, np.int64)
                slot[c.member_index] = np.arange(c.member_index.size)
                member_row = np.full(c.member_index.size, -1, np.int64)
                owned = np.flatnonzero(self._particles.owned & (member_of >= 0))
                member_row[slot[ids[owned]]] = owned
                self._clump_rows = (member_of, member_row)
        return self._clump_rows

    def set_clump_share(self, active, booked):
        """The clumps this process advances (``active``, ascending) and those whose energy terms it
        books (``booked``, bool per clump): a distributed run's choice (the clumps it owns a member
        of, and one rank per clump); a serial engine advances and books them all."""
        self._clump_share = (np.asarray(active, np.int64), np.asarray(booked, np.bool_))

    def clump_share(self):
        """(active, booked) of :meth:`set_clump_share` (by default every clump, every clump)."""
        if self._clump_share is None or self._clump_share[1].size != self.clumps.count:
            self.set_clump_share(np.arange(self.clumps.count), np.ones(self.clumps.count, np.bool_))
        return self._clump_share

    @property
    def acceleration(self) -> np.ndarray:
        """Last step's (v^{n+½} − v^{n−½})/Δt per particle (n, 3), for the contact dashpot;
        current, like :attr:`particles`."""
        self.write_back()
        return self._acceleration

    @acceleration.setter
    def acceleration(self, value):
        self._copies_hold_state = False
        self._acceleration = value

    def set_materials(self, materials):
        """Replace the contact parameters (friction, restitution, stiffness ratio, rolling
        resistance) in place, keeping positions, velocities and the contact history.
        Densities and Young's moduli (masses, stiffnesses, Δt) and whether any pair has
        rolling resistance must stay as they are."""
        new = [m if isinstance(m, Material) else Material(**m) for m in materials]
        if len(new) != len(self.materials):
            raise ValueError(f"Engine.set_materials: {len(new)} materials given, the engine has {len(self.materials)}")
        for k, (a, b) in enumerate(zip(self.materials, new, strict=True)):
            if (a.density, a.young, a.poisson) != (b.density, b.young, b.poisson):
                raise ValueError(f"Engine.set_materials: material {k} changes density, young or poisson; "
                                 "only contact parameters may change")
        table = pair_table(new)
        if bool(np.any(table[:, :, PAIR_ROLLING_STIFFNESS] > 0.0)) != self.neighbors.rolling:
            raise ValueError("Engine.set_materials: rolling stiffness cannot be switched on or off in a run")
        self.materials = new
        self.pair_params = table

    # ------------------------------------------------------------------ setup
    def _setup_facet_topology(self):
        tris, edges, mats, meshes, v_off, e_off = [], [], [], [], 0, 0
        self._vertex_offsets = [0]
        for k, mesh in enumerate(self.facets):
            meshes.append(np.full(mesh.triangles.shape[0], k, np.int32))
            tris.append(mesh.triangles.astype(np.int64) + v_off)
            edges.append(mesh.triangle_edges + e_off)
            mats.append(np.full(mesh.triangles.shape[0], mesh.material, np.int32))
            v_off += mesh.vertices.shape[0]
            e_off += mesh.n_edges
            self._vertex_offsets.append(v_off)
        self._triangles = np.concatenate(tris) if tris else np.zeros((0, 3), np.int64)
        self._triangle_edges = np.concatenate(edges) if edges else np.zeros((0, 3), np.int64)
        self._triangle_material = np.concatenate(mats) if mats else np.zeros(0, np.int32)
        self._triangle_mesh = np.concatenate(meshes) if meshes else np.zeros(0, np.int32)
        # the last step's vertex forces (the meshes' ``vertex_force``, after a checkpoint too)
        self._vertex_force = np.concatenate([m.vertex_force for m in self.facets]) if self.facets \
            else np.zeros((0, 3))
        self._facet_vertices_known = np.concatenate([m.vertices for m in self.facets]) if self.facets \
            else np.zeros((0, 3))
        self._facet_vertices = np.zeros((v_off, 3))  # all meshes' vertices, velocities and impulses
        self._facet_vertex_velocity = np.zeros((v_off, 3))
        self._facet_impulse = np.zeros((v_off, 3))

    def _allocate_pair_arrays(self, m):
        """Per-pair results of the last step: the force and torque on j (rows in the
        j-side order of ``neighbors.j_slot``), the overlap (list order)."""
        self.j_rec = np.zeros((m, 6))  # per pair, in j-side order (neighbors.j_slot): force and torque on j
        self.pair_ov = np.full(m, np.nan)  # overlap; NaN: previous step unknown (see fused._pair_block)
        m_f = self.neighbors.f_tri.size
        self.facet_force = np.zeros((m_f, 3))
        self.facet_lambda = np.zeros((m_f, 3))
        self.facet_active = np.zeros(m_f, np.bool_)

    @property
    def pair_force(self):
        """Force on i of each listed pair in the last step (zero when not in contact)."""
        return -self.j_rec[self.neighbors.j_slot, 0:3]

    @property
    def pair_overlap(self):
        """Overlap δ of each listed pair in the last step (≤ 0: not in contact)."""
        return self.pair_ov

    def critical_timestep(self):
        """Δt_crit: linear law min √(m_i/k_n,i), k_n,i = 2 E r_i (a sphere against its
        equal); Hertz law the P-wave estimate min r √(ρ/E) (docs/design.md §2.14)."""
        p = self.particles
        E = self.young[p.material]
        if p.n == 0:
            local = math.inf
        elif self.law == HERTZ:
            rho = self.density[p.material]
            local = float(np.min(p.radius * np.sqrt(rho / E)))
        elif self.clumps.count:  # a member by its clump's critical mass, from every particle's radius
            radius = p.radius if self.domain is None else self.global_particles().radius
            critical = self.clumps.critical_mass(radius)
            member_of, _ = self.clump_rows()
            mass = np.where(member_of >= 0, critical if self.domain is None else critical[self.domain.ids], p.mass)
            local = float(np.min(np.sqrt(mass / (2.0 * E * p.radius))))
        else:
            local = float(np.min(np.sqrt(p.mass / (2.0 * E * p.radius))))
        return self.runner.minimum(local)

    # ------------------------------------------------------------------ the step
    def step(self):
        """Advance one time step Δt (sequence in the module docstring)."""
        self.run(1)

    def run(self, nsteps):
        """Advance ``nsteps`` steps (by the run object, :attr:`runner`)."""
        self.runner.run(self, int(nsteps))

    def update_wall_forces(self):
        """Make ``wall.force`` the last step's again (collective when distributed), after runs
        with ``wall_forces_each_run = False``."""
        if self.wall_forces_stale:
            self.runner.wall_totals(self)
            self.wall_forces_stale = False

    def start_external_run(self):
        """For a caller that calls :func:`fused.advance` from its own compiled loop (the
        FE–DE coupling, :mod:`cosim.compiled_coupling`): what :meth:`run` does before its
        kernel call — boundary jumps booked, the state in the sorted copies, the facet
        impulses loaded — and the kernel's arguments after ``nsteps``: the eight named tuples of
        :mod:`de_domain.state`, the energy books and the clock. The facet vertices, their
        velocities and impulses are the arrays of the returned ``FacetMeshes``, all meshes
        concatenated (mesh k's rows from ``facet_rows(k)``); the caller may set them between
        kernel calls, and books the work of what it moves (:func:`fused.facet_jump_work`).
        Then :meth:`end_external_run`. Returns None, and does nothing, when the lists are
        due for a rebuild or the spatial order for a refresh (:meth:`run` does those), and
        for a distributed engine."""
        if self.domain is not None:
            return None
        boundaries = self.boundaries()
        if self.steps_before_reorder() <= 0 or self.lists_due(boundaries):
            return None
        self.book_boundary_jumps(boundaries)
        copies = self._sorted_copies()
        vertices, vertex_velocity = boundaries.facets
        facet_state = (vertices, vertex_velocity, self._load_facet_impulses())
        return self._kernel_state(boundaries.walls, facet_state, copies), self._books, self._clock_at_start()

    def steps_before_reorder(self):
        """DEM steps left before the spatial order is refreshed (a run stops there)."""
        return self.neighbors.perm_step + fused.PERM_EVERY - self.step_count

    def facet_rows(self, k):
        """Rows of facet mesh ``k`` in the concatenated vertex arrays."""
        return slice(self._vertex_offsets[k], self._vertex_offsets[k + 1])

    @property
    def boundary_jump_work(self):
        """Work (J) of walls and facet vertices displaced from outside, booked so far."""
        return self._jump_work

    def end_external_run(self, steps, jump_work):
        """After :meth:`start_external_run` and ``steps`` kernel steps: the clock, the walls'
        and facets' state handed back to their objects (as after :meth:`run`), the facet
        velocities too; ``jump_work``: :attr:`boundary_jump_work` with the caller's
        bookings added, window by window (the order :meth:`run` adds them in)."""
        self._finish_run(steps, self._walls_state, self._facet_vertices, self._facet_impulse)
        for k, mesh in enumerate(self.facets):
            mesh.vertex_velocity[:] = self._facet_vertex_velocity[self.facet_rows(k)]
        self._jump_work = float(jump_work)

    def _wall_arrays(self):
        """(point, normal, velocity, material) of the plane walls, in arrays the engine keeps
        (the same objects every call: see :mod:`numba_support.dispatch`) and the walls hold
        their state in (:meth:`PlaneWall.bind`; bound again if the list of walls changed, or
        a wall was bound to another engine since)."""
        state = self._walls_state
        walls = self.walls
        if state is None or len(state[3]) != len(walls) or \
                not all(w.bound_to is state and w.bound_row == k for k, w in enumerate(walls)):
            n = len(walls)
            state = self._walls_state = (np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3)), np.zeros(n, np.int32))
            for k, wall in enumerate(walls):
                wall.bind(state, k)
        return state

    # ------------------------------------------------------------------ step interface (de_domain.runs)
    def boundaries(self):
        """The plane walls' and facet meshes' state in the arrays a run advances
        (:data:`Boundaries`; read once per run: the steps advance them and write them back)."""
        return Boundaries(self._wall_arrays(), self._gather_facets())

    def update_lists(self, boundaries):
        """Rebuild the lists of one process if they are due (:meth:`lists_due`) or the
        spatial order is due for a refresh, carrying the contact history."""
        p = self._particles
        nl = self.neighbors
        wp, wn, _, _ = boundaries.walls
        vertices = boundaries.facets[0]
        refresh = nl.perm is not None and self.steps_before_reorder() <= 0
        if refresh or self.lists_due(boundaries):
            self.write_back()  # the build reads, reorders and rewrites the public arrays
            if refresh or nl.perm is None:
                nl.perm_step = self.step_count
            nl.build(p.pos, p.radius, p.n, vertices, self._triangles, wp, wn, ghost=p.ghost,
                     carried=self.take_pending_records(), new_order=refresh, body=self.clump_rows()[0])
            self._allocate_pair_arrays(nl.pair_js.size)

    def install_rows(self, rows, ghost, ids, carried):
        """A distributed rebuild's new rows (``rows``: every per-particle array, ``acceleration``,
        ascending global ``ids``; ``ghost`` marks the copies of other ranks' particles) and
        their lists, built in a new spatial order with the ``carried`` contact history."""
        self.particles = Particles.from_arrays(rows, 0)
        self._particles.ghost = ghost
        self.acceleration = rows["acceleration"]
        p = self._particles
        boundaries = self.boundaries()
        wall_point, wall_normal, _, _ = boundaries.walls
        self.neighbors.build(p.pos, p.radius, p.n, boundaries.facets[0], self._triangles, wall_point, wall_normal,
                             ghost=ghost, ids=ids, carried=carried, new_order=True, body=self.clump_rows()[0])
        self._allocate_pair_arrays(self.neighbors.pair_js.size)

    def take_pending_records(self):
        """The contact history a checkpoint left for the first list build (None once taken)."""
        records, self._pending_records = self._pending_records, None
        return records

    def lists_due(self, boundaries):
        """Must the lists be built before the next step: none yet or for other rows, or owned
        particles, walls or facet vertices moved more than the skin allows since the last
        build (read from the sorted copies when they hold the state: the largest displacement
        does not depend on the order; the particles' is then the last step's,
        :attr:`particle_shift`, if a step was made on them)?"""
        p = self._particles
        nl = self.neighbors
        if nl.perm is None or nl.ref_pos is None or nl.ref_pos.shape[0] != p.n:
            return True
        wall_point, wall_normal, _, _ = boundaries.walls
        vertices = boundaries.facets[0]
        if self._copies_hold_state:  # nothing moved the particles since the last step (if any) on them
            copies = self._sorted
            return nl.needs_rebuild(copies.pos, p.n, vertices, wall_point, wall_normal, ref_pos=copies.ref_pos,
                                    particle_shift=self.particle_shift)
        return nl.needs_rebuild(p.pos, p.n, vertices, wall_point, wall_normal)

    @property
    def particle_shift(self):
        """The owned particles' largest displacement since the last list build, after the last
        step (< 0: not known) — what the rebuild test reads; a distributed run sets it to the
        largest over the ranks."""
        return float(self._clock[CLOCK_PARTICLE_SHIFT])

    @particle_shift.setter
    def particle_shift(self, value):
        self._clock[CLOCK_PARTICLE_SHIFT] = value

    @property
    def copies_hold_state(self):
        """Do the spatially sorted copies, not :attr:`particles`' arrays, hold the current state?"""
        return self._copies_hold_state

    def _kernel_state(self, walls, facet_state, sorted_copies):
        """The named tuples of :mod:`de_domain.state` for :func:`fused.advance`, over the
        public arrays (through ``perm``) or over the spatially sorted copies."""
        p = self._particles
        nl = self.neighbors
        in_order = sorted_copies is not None
        settings = StepSettings(law=self.law, dt=self.dt, gravity=self.gravity, local_damping=self.local_damping,
                                viscous_damping=self.viscous_damping,
                                has_constraints=bool(p.blocked.any() or p.prescribed.any()), rolling=nl.rolling,
                                in_order=in_order, skin=float(nl.skin))
        if in_order:
            particles = sorted_copies
            if self._identity_perm.size != p.n:
                self._identity_perm = np.arange(p.n, dtype=np.int32)
            perm = self._identity_perm
        else:
            particles = self._public_arrays()
            perm = nl.perm
        pairs = PairList(perm=perm, i_start=nl.i_start, pair_js=nl.pair_js, j_start=nl.j_start, j_slot=nl.j_slot,
                         tangential=nl.ht, rolling_moment=nl.hr, j_record=self.j_rec, overlap=self.pair_ov)
        point, normal, velocity, material = walls
        plane_walls = PlaneWalls(point=point, normal=normal, velocity=velocity, material=material,
                                 ref_point=nl.ref_wall_point, start=nl.w_start, wall=nl.w_idx, history=nl.w_hist,
                                 normal_force=nl.w_fn, force=nl.w_force)
        vertices, vertex_vel, vertex_impulse = facet_state
        ref_vertices = nl.ref_vertices if nl.ref_vertices is not None else vertices
        meshes = FacetMeshes(vertices=vertices, vertex_velocity=vertex_vel, triangles=self._triangles,
                             triangle_edges=self._triangle_edges, triangle_material=self._triangle_material,
                             triangle_mesh=self._triangle_mesh, vertex_force=self._vertex_force,
                             vertex_impulse=vertex_impulse, ref_vertices=ref_vertices)
        candidates = FacetCandidates(particle_index=nl.perm, start=nl.f_start, triangle=nl.f_tri,
                                     history=nl.facet_history, active=self.facet_active, force=self.facet_force,
                                     barycentric=self.facet_lambda)
        params = ContactParameters(young=self.young, pair_params=self.pair_params)
        return settings, particles, params, pairs, plane_walls, meshes, candidates, self._clump_arrays(in_order)

    def _clump_arrays(self, in_order):
        """:data:`ClumpArrays` over the kernel's particle rows: the public ones, or the spatially
        sorted copies (``in_order``: members and ``member_of`` through the spatial order)."""
        c = self.clumps
        if not c.count:
            if self._free_member_of.size != self._particles.n:
                self._free_member_of = np.full(self._particles.n, -1, np.int32)
            member_of, member_row = self._free_member_of, c.member_index
        else:
            member_of, member_row = self.clump_rows()
            if in_order:  # into buffers kept by the engine: the kernel's cached entry needs the same arrays
                if self._sorted_clump_rows is None or self._sorted_clump_rows[0].size != member_of.size:
                    self._sorted_clump_rows = (np.empty_like(member_of), np.empty_like(member_row))
                sorted_of, sorted_row = self._sorted_clump_rows
                np.take(member_of, self.neighbors.perm, out=sorted_of)
                held = member_row >= 0
                sorted_row[:] = -1
                sorted_row[held] = self.neighbors.iperm[member_row[held]]
                member_of, member_row = sorted_of, sorted_row
        if self._member_load.shape[0] != c.member_index.size:
            self._member_load = np.zeros((c.member_index.size, MEMBER_COLUMNS))
        active, booked = self.clump_share()
        return ClumpArrays(member_of=member_of, pos=c.pos, vel=c.vel, quat=c.quat, angmom=c.angmom, mass=c.mass,
                           moments=c.moments, member_start=c.member_start, member_row=member_row,
                           member_body=c.member_body, force=c.force, torque=c.torque, member_load=self._member_load,
                           active=active, booked=booked)

    def _public_arrays(self):
        """The particle arrays in the public order, as the kernels take them."""
        p = self._particles
        return ParticleArrays(pos=p.pos, vel=p.vel, accel=self._acceleration, angvel=p.angvel, radius=p.radius,
                              mass=p.mass, inertia=p.inertia, material=p.material, blocked=p.blocked,
                              prescribed=p.prescribed, prescribed_velocity=p.prescribed_velocity, force=p.force,
                              torque=p.torque, ref_pos=self.neighbors.ref_pos, ghost=p.ghost)

    def _sorted_copies(self):
        """Particle arrays gathered into the spatial order (index = perm position), in
        buffers the engine keeps (made again only when the particle count changes, or
        constraints appear: without them the constraint arrays are not read); they hold
        the state from then on, until :meth:`write_back`. Gathered only if they do not
        hold it already."""
        if self._copies_hold_state:
            return self._sorted
        p = self._particles
        constraints = bool(p.blocked.any() or p.prescribed.any())
        copies = self._sorted
        if copies is None or copies.pos.shape[0] != p.n or (constraints and copies.blocked is p.blocked):
            n = p.n
            blocked, prescribed, prescribed_velocity = (
                (np.zeros((n, 6), np.bool_), np.zeros((n, 6), np.bool_), np.zeros((n, 6)))
                if constraints else (p.blocked, p.prescribed, p.prescribed_velocity))
            copies = self._sorted = ParticleArrays(
                pos=np.empty((n, 3)), vel=np.empty((n, 3)), accel=np.empty((n, 3)), angvel=np.empty((n, 3)),
                radius=np.empty(n), mass=np.empty(n), inertia=np.empty(n), material=np.empty(n, np.int32),
                blocked=blocked, prescribed=prescribed, prescribed_velocity=prescribed_velocity,
                force=np.zeros((n, 3)), torque=np.zeros((n, 3)), ref_pos=np.empty((n, 3)),
                ghost=np.empty(n, np.bool_))
        fused.gather_in_order(self.neighbors.perm, self._public_arrays(), copies, constraints)
        self._copies_hold_state = True
        self._clock[CLOCK_PARTICLE_SHIFT] = -1.0  # measured again before the first step on them
        return copies

    def advance(self, nsteps, boundaries):
        """Fused steps of one process until ``nsteps`` are done or the lists need a rebuild;
        returns the steps done.

        Runs of ``SORTED_MIN_STEPS`` or more, and every run of a ``keep_sorted``
        engine, work on copies of the particle arrays in the spatial order (gathered
        before, scattered after unless ``keep_sorted``: cache-friendly); shorter ones in
        place through ``perm``. Both give bit-identical results."""
        p = self._particles
        clock = self._clock_at_start()
        copies = None
        if p.n_owned == p.n and (nsteps >= SORTED_MIN_STEPS or self.keep_sorted or self._copies_hold_state):
            copies = self._sorted_copies()
        walls = boundaries.walls
        vertices, vertex_vel = boundaries.facets
        impulse = self._load_facet_impulses()
        self._advance_kernel(nsteps, *self._kernel_state(walls, (vertices, vertex_vel, impulse), copies),
                             self._books, clock)
        done = int(clock[CLOCK_STEPS])
        self._finish_run(done, walls, vertices, impulse)
        return done

    def _load_facet_impulses(self):
        """The meshes' vertex impulses, copied into the concatenated array the kernel adds to."""
        impulse = self._facet_impulse
        for k, mesh in enumerate(self.facets):
            impulse[self.facet_rows(k)] = mesh.vertex_impulse
        return impulse

    def _finish_run(self, steps, walls, vertices, impulse):
        """After ``steps`` kernel steps from the clock of :meth:`_clock_at_start`: the sorted
        copies written back (unless ``keep_sorted``), the clock, the walls and the facets."""
        if not self.keep_sorted:
            self.write_back()
        self.time = float(self._clock[CLOCK_TIME])
        self.step_count += int(steps)
        self._finish_walls(walls[0])
        self._finish_facets(vertices, impulse)

    def write_back(self):
        """Scatter the spatially sorted copies back to the public arrays, if they hold the
        state (the public arrays then do, and the next run gathers them again)."""
        if self._copies_hold_state:
            self._copies_hold_state = False
            fused.scatter_in_order(self.neighbors.perm, self._sorted, self._public_arrays())

    def step_on_copies(self, boundaries, share_member_loads):
        """One step of a distributed run on this rank's spatially sorted copies (gathered
        first if they do not hold the state; the facet vertex forces and impulses are summed
        over the ranks afterwards, by the caller: :meth:`set_facet_vertex_forces`), with the
        arrays of :meth:`boundaries` (advanced in place). With clumps, the step stops after the
        contacts for ``share_member_loads(clumps)``, which fills the ``member_load`` rows of the
        members other ranks own (:data:`~de_domain.state.ClumpArrays`). Returns the copies (the
        caller exchanges their ghost rows) and whether this rank's particles, walls or vertices
        call for a list rebuild."""
        copies = self._sorted_copies()
        walls = boundaries.walls
        clock = self._clock_at_start()
        vertices, vertex_vel = boundaries.facets
        facet_state = (vertices, vertex_vel, self._facet_impulse)  # this rank's impulse: not used
        state = self._kernel_state(walls, facet_state, copies)
        if not self.clumps.count:
            due = self._advance_kernel(1, *state, self._books, clock)
        else:
            settings, particles, params, pairs, plane_walls, meshes, candidates, clumps = state
            n = particles.pos.shape[0]
            buffers = self._step_buffers
            if buffers is None or buffers.shift.size != (n + fused.PBLOCK - 1) // fused.PBLOCK:
                buffers = self._step_buffers = fused.step_buffers(n, clumps.mass.size)
            self._forces_kernel(*state, buffers)
            self._collect_kernel(particles, clumps)
            share_member_loads(clumps)
            due = self._finish_kernel(settings, particles, plane_walls, meshes, candidates, clumps, buffers,
                                      self._books, clock)
        self.time = float(clock[CLOCK_TIME])
        self.step_count += 1
        self._wall_points_known[:] = walls[0]
        for k, mesh in enumerate(self.facets):
            mesh.vertices[:] = vertices[self.facet_rows(k)]
        self._facet_vertices_known[:] = vertices
        return copies, due

    def set_facet_vertex_forces(self, triangle, weights, force):
        """This step's facet vertex forces from the contacts of all ranks — ``triangle`` (c,),
        the closest point's barycentric ``weights`` (c, 3) and the ``force`` on the sphere
        (c, 3), in (global id, triangle) order — and the meshes' impulses += F Δt."""
        vertex_force = self._vertex_force
        vertex_forces_of_rows(vertex_force, self._triangles, triangle, weights, force)
        for k, mesh in enumerate(self.facets):
            part = self.facet_rows(k)
            mesh.vertex_impulse[:] += vertex_force[part] * self.dt
            mesh.vertex_force = vertex_force[part].copy()
            mesh.force = mesh.vertex_force.sum(axis=0)

    def _finish_walls(self, wall_point):
        nl = self.neighbors
        if not self.walls:
            return
        totals = self._wall_totals(len(self.walls), nl.w_idx, nl.w_particle, nl.w_order, nl.w_force, fused.PBLOCK)
        for w, wall in enumerate(self.walls):
            wall.force = totals[w]  # rows of a new array
        self._wall_points_known[:] = wall_point

    def _clock_at_start(self):
        """The kernel's clock (kept by the engine), at this time and no step done."""
        self._clock[CLOCK_TIME] = self.time
        self._clock[CLOCK_STEPS] = 0.0
        return self._clock

    # ------------------------------------------------------------------ boundaries
    def _gather_facets(self):
        """(vertices, velocities) of all facet meshes, copied into the arrays the engine keeps."""
        for k, mesh in enumerate(self.facets):
            part = slice(self._vertex_offsets[k], self._vertex_offsets[k + 1])
            self._facet_vertices[part] = mesh.vertices
            self._facet_vertex_velocity[part] = mesh.vertex_velocity
        return self._facet_vertices, self._facet_vertex_velocity

    def _finish_facets(self, vertices, impulse):
        """Scatter the advanced vertices, the last step's vertex forces and the
        accumulated impulses back to the meshes."""
        for k, mesh in enumerate(self.facets):
            part = slice(self._vertex_offsets[k], self._vertex_offsets[k + 1])
            mesh.vertices[:] = vertices[part]
            mesh.vertex_force = self._vertex_force[part].copy()
            mesh.vertex_impulse[:] = impulse[part]
            mesh.force = mesh.vertex_force.sum(axis=0)
        self._facet_vertices_known[:] = vertices

    def book_boundary_jumps(self, boundaries):
        """Work of walls/facets displaced from outside since the engine last left them:
        −F_on_wall · Δx (last step's force), ``boundaries`` saying where they are now
        (:meth:`boundaries`). One compiled call (:func:`fused.boundary_jumps`) unless a wall
        moved: then its last force is made current first (collective when distributed)."""
        wall_point = boundaries.walls[0]
        vertices = boundaries.facets[0]
        walls_moved, work = fused.boundary_jumps(wall_point, self._wall_points_known, vertices,
                                                 self._facet_vertices_known, self._vertex_force)
        if walls_moved:
            self.update_wall_forces()
            for w in np.flatnonzero(np.any(wall_point != self._wall_points_known, axis=1)):
                work -= float(self.walls[w].force @ (wall_point[w] - self._wall_points_known[w]))
            self._wall_points_known[:] = wall_point
        if self.runner.is_root:  # the walls are global: book once
            self._jump_work += work

    # ------------------------------------------------------------------ energy
    def _energy_reset(self):
        # slots state.BOOK_*: state (STATE_TERMS), accumulated / first / last rate terms
        # (RATE_TERMS), initial total, initialised flag (fused.record_energy writes them)
        self._books = np.zeros(N_BOOKS)
        self._jump_work = 0.0

    @staticmethod
    def _book(books, offset, terms):
        return {k: float(books[offset + m]) for m, k in enumerate(terms)}

    def energy(self):
        """Energy balance at time tⁿ of the last step (docs/design.md §2.15).

        State terms (kinetic at v^n, gravity −Σ m g·x, elastic normal/tangential/
        rolling), cumulative work in (walls/facets, prescribed DOFs) and dissipation
        (friction incl. released springs, contact damping, background damping),
        integrated with the trapezoidal rule over the recorded steps, and
        ``residual = total − (initial_total + work − dissipated)``. A distributed
        engine sums the books of all ranks in rank order (collective).
        """
        books = self._books.copy()
        if books[BOOK_INITIALISED] == 0.0:  # before the first step: current velocities, no contacts yet
            p = self.particles
            mine = p.owned
            kinetic = (0.5 * np.sum(p.mass[mine, None] * p.vel[mine] ** 2),
                       0.5 * np.sum(p.inertia[mine, None] * p.angvel[mine] ** 2),
                       -np.sum(p.mass[mine] * (p.pos[mine] @ self.gravity)))
            for k, value in enumerate(kinetic):  # kinetic_translational, kinetic_rotational, gravity
                books[BOOK_STATE + k] = float(value)
        jump_work = self._jump_work
        books = self.runner.books(self, books)
        jump_work = self.runner.broadcast(jump_work)  # booked on the root only
        initialised = books[BOOK_INITIALISED] != 0.0
        state = self._book(books, BOOK_STATE, STATE_TERMS)
        acc = self._book(books, BOOK_ACCUMULATED, RATE_TERMS)
        first = self._book(books, BOOK_FIRST, RATE_TERMS)
        last = self._book(books, BOOK_LAST, RATE_TERMS)
        out = dict(state)
        out["kinetic"] = out["kinetic_translational"] + out["kinetic_rotational"]
        for k in RATE_TERMS:
            out[k] = acc[k] - 0.5 * (first[k] + last[k])
        out["work_walls"] += jump_work
        out["total"] = sum(state.values())
        out["initial_total"] = float(books[BOOK_INITIAL_TOTAL]) if initialised else out["total"]
        out["work"] = sum(out[k] for k in WORK_TERMS)
        out["dissipated"] = sum(out[k] for k in DISSIPATION_TERMS)
        out["residual"] = out["total"] - (out["initial_total"] + out["work"] - out["dissipated"])
        return out

    def global_particles(self):
        """Every particle in global-id order: a serial engine's own ``particles``; a
        distributed engine's owned rows of all ranks, gathered on every rank
        (collective), with ``acceleration`` as an extra attribute."""
        if self.domain is None:
            return self.particles
        rows = self.runner.owned_rows(self)
        out = Particles.from_arrays(rows, rows["id"].size)
        out.acceleration = rows["acceleration"]
        return out

    # ------------------------------------------------------------------ contacts
    @property
    def wall_history(self):
        """Dense (n, n_walls, 6) copy of the plane-wall contact history (stored sparse)."""
        nl = self.neighbors
        out = np.zeros((self._particles.n, len(self.walls), 6))
        out[nl.w_particle, nl.w_idx] = nl.w_hist
        return out

    @property
    def wall_fn(self):
        """Dense (n, n_walls) copy of the last step's normal force per sphere–wall contact."""
        nl = self.neighbors
        out = np.zeros((self._particles.n, len(self.walls)))
        out[nl.w_particle, nl.w_idx] = nl.w_fn
        return out

    def wall_contact_particles(self, wall_index):
        """Indices of the particles touching plane wall ``wall_index`` in the last step
        (a light subset of :meth:`contacts`); a distributed engine's: their global ids,
        gathered from every rank (collective)."""
        nl = self.neighbors
        live = (nl.w_fn > 0.0) & (nl.w_idx == wall_index)
        if self.domain is None:
            return np.sort(nl.w_particle[live].astype(np.int64))
        ids = self.domain.ids[nl.w_particle[live]]
        return np.sort(self.runner.concatenate(ids))

    def memory_bytes(self):
        """nbytes of every per-particle, per-contact and per-clump array the engine holds, by name."""
        out = {f"particles.{k}": v.nbytes for k, v in self.particles.arrays().items()}
        out["acceleration"] = self.acceleration.nbytes
        for k in ("j_rec", "pair_ov", "facet_force", "facet_lambda", "facet_active"):
            out[k] = getattr(self, k).nbytes
        out.update(self.neighbors.memory_bytes())
        p = self.particles
        if p.n:  # buffers of the copies in the spatial order, kept after the first run on them
            per = 6 * 24 + 3 * 8 + 4 + 24 + 1  # pos vel acc angvel force torque, radius mass inertia, material,
            if p.blocked.any() or p.prescribed.any():  # ref_pos, ghost
                per += 6 + 6 + 48
            out["run.sorted_copies"] = per * p.n
        out["particles.ghost"] = p.ghost.nbytes
        if self.clumps.count:  # every clump on every rank, and the members' loads of a step
            out.update({f"clumps.{k}": v.nbytes for k, v in self.clumps.arrays().items()})
            out["clumps.member_load"] = self._member_load.nbytes
        if self.domain is not None:
            out["domain.ids"] = self.domain.ids.nbytes
            if self.domain.exchange is not None:
                out["domain.exchange"] = self.domain.exchange.buffer_bytes
        return out

    def contacts(self):
        """Active contacts of the last step (forces at tⁿ; positions are the current ones).
        A distributed engine's are this rank's: indices are rows of ``particles`` (global
        ids: ``domain.ids[i]``), and a pair between two ranks is listed on both.

        Sphere pairs: ``i``, ``j``, ``force`` (on i), ``overlap``, ``normal`` (i → j),
        ``branch`` (x_j − x_i), ``point`` (overlap midpoint).
        Walls: ``wall_particle``, ``wall_index``, ``wall_force`` (on the particle),
        ``wall_point`` (overlap midpoint). Facets: ``facet_particle``, ``facet_triangle`` (global
        index over ``facets``), ``facet_force`` (on the particle), ``facet_lambda``
        (barycentric weights of the closest point), ``facet_point`` (the closest point).
        """
        p = self.particles
        nl = self.neighbors
        active = np.nonzero(self.pair_overlap > 0.0)[0]
        i = nl.pair_i[active].astype(np.int64)
        j = nl.pair_j[active].astype(np.int64)
        order = np.argsort(i * p.n + j)  # canonical (i, j) order
        active, i, j = active[order], i[order], j[order]
        branch = p.pos[j] - p.pos[i]
        dist = np.linalg.norm(branch, axis=1)
        normal = branch / dist[:, None] if dist.size else branch
        overlap = self.pair_overlap[active]
        point = p.pos[i] + (p.radius[i] - 0.5 * overlap)[:, None] * normal
        out = {"i": i, "j": j, "force": self.pair_force[active], "overlap": overlap, "normal": normal,
               "branch": branch, "point": point}
        live = np.nonzero(nl.w_fn > 0.0)[0]
        nw = max(len(self.walls), 1)
        live = live[np.argsort(nl.w_particle[live].astype(np.int64) * nw + nl.w_idx[live])]
        wp = nl.w_particle[live].astype(np.int64)
        wi = nl.w_idx[live].astype(np.int64)
        if wp.size:
            wn = np.array([w.normal for w in self.walls])[wi]
            wf = nl.w_fn[live][:, None] * wn + nl.w_hist[live, :3]
            dist = np.einsum("ij,ij->i", p.pos[wp] - np.array([w.point for w in self.walls])[wi], wn)
            wpoint = p.pos[wp] - (0.5 * (p.radius[wp] + dist))[:, None] * wn  # overlap midpoint
        else:
            wf = np.zeros((0, 3))
            wpoint = np.zeros((0, 3))
        out.update(wall_particle=wp, wall_index=wi, wall_force=wf, wall_point=wpoint)
        fa = np.any(self.facet_force != 0.0, axis=1)
        particles_of = np.repeat(np.arange(nl.f_start.size - 1), np.diff(nl.f_start))
        triangle = nl.f_tri[fa].astype(np.int64)
        vertices = np.concatenate([m.vertices for m in self.facets]) if self.facets else np.zeros((0, 3))
        point = np.einsum("ca,cad->cd", self.facet_lambda[fa], vertices[self._triangles[triangle]])
        out.update(facet_particle=particles_of[fa], facet_triangle=triangle, facet_force=self.facet_force[fa],
                   facet_lambda=self.facet_lambda[fa], facet_point=point)
        return out

    # ------------------------------------------------------------------ checkpoint
    def save_checkpoint(self, path):
        """Write the full state (particles, boundaries, contact history, energy books) as npz.

        A distributed engine (collective) gathers everything in global-id order and
        rank 0 writes one file, with the contact history as records keyed by global
        ids: it resumes with any number of ranks, or none (:meth:`load_checkpoint`)."""
        if self.domain is None:
            particles, acceleration, books, jump = self.particles, self.acceleration, self._books, self._jump_work
        else:
            self.update_wall_forces()
            particles = self.global_particles()
            acceleration = particles.acceleration
            books = self.runner.books(self, self._books)
            jump = self.runner.broadcast(self._jump_work)
        data = {f"p_{k}": v for k, v in particles.arrays().items()}
        data["n_owned"] = np.int64(particles.n_owned)
        for field in dataclasses.fields(Material):
            data[f"mat_{field.name}"] = np.array([getattr(m, field.name) for m in self.materials])
        for k in ("point", "normal", "velocity", "force"):
            data[f"wall_{k}"] = np.array([getattr(w, k) for w in self.walls]).reshape(-1, 3)
        data["wall_point_known"] = np.array(self._wall_points_known).reshape(-1, 3)
        data["wall_material"] = np.array([w.material for w in self.walls], np.int64)
        data["n_facets"] = np.int64(len(self.facets))
        for k, mesh in enumerate(self.facets):
            for name in ("vertices", "triangles", "vertex_velocity", "vertex_force", "vertex_impulse", "force"):
                data[f"facet{k}_{name}"] = getattr(mesh, name)
            data[f"facet{k}_vertices_known"] = self._facet_vertices_known[self.facet_rows(k)]
            data[f"facet{k}_material"] = np.int64(mesh.material)
            if mesh.source_nodes is not None:
                data[f"facet{k}_source_nodes"] = mesh.source_nodes
        if self.domain is None:
            for k, v in self.neighbors.state().items():
                data[f"nl_{k}"] = v
            for name in ("j_rec", "pair_ov", "facet_force", "facet_lambda"):
                data[name] = getattr(self, name)
        else:
            data["nl_skin"] = np.float64(self.neighbors.skin)
            for k, v in self.runner.contact_records(self)._asdict().items():
                data[f"records_{k}"] = v
        if self.clumps.count:
            for k, v in self.clumps.arrays().items():
                data[f"clump_{k}"] = v
        data["gravity"] = self.gravity
        data["acceleration"] = acceleration
        data["config"] = np.array([self.dt, self.safety_factor, self.local_damping, self.viscous_damping,
                                   self.time])
        data["step_count"] = np.int64(self.step_count)
        data["contact_law"] = np.array(self.contact_law)
        data["energy_books"] = books
        data["energy_jump"] = np.array(jump)
        if self.runner.is_root:
            np.savez(path, **data)
        self.runner.barrier()

    @classmethod
    def load_checkpoint(cls, path, comm=None):
        """Rebuild an Engine from :meth:`save_checkpoint` (with ``comm``: distributed,
        over any number of ranks, from a serial or a distributed checkpoint);
        continuing is bit-identical."""
        with np.load(path, allow_pickle=False) as f:
            d = {k: f[k] for k in f.files}
        particles = Particles.from_arrays({k: d[f"p_{k}"] for k in ARRAY_FIELDS}, int(d["n_owned"]))
        names = [fl.name for fl in dataclasses.fields(Material)]
        materials = [Material(**{k: float(d[f"mat_{k}"][m]) for k in names})
                     for m in range(d["mat_density"].size)]
        walls = []
        for w in range(d["wall_point"].shape[0]):
            wall = PlaneWall(d["wall_point"][w], d["wall_normal"][w], int(d["wall_material"][w]),
                             d["wall_velocity"][w])
            wall.normal = d["wall_normal"][w].copy()
            wall.force = d["wall_force"][w].copy()
            walls.append(wall)
        facets = []
        for k in range(int(d["n_facets"])):
            mesh = FacetMesh(d[f"facet{k}_vertices"], d[f"facet{k}_triangles"], int(d[f"facet{k}_material"]),
                             d.get(f"facet{k}_source_nodes"))
            for name in ("vertex_velocity", "vertex_force", "vertex_impulse", "force"):
                setattr(mesh, name, d[f"facet{k}_{name}"].copy())
            facets.append(mesh)
        dt, safety, local, viscous, time = d["config"]
        clumps = Clumps(**{k: d[f"clump_{k}"] for k in Clumps.FIELDS}) if "clump_mass" in d else None
        engine = cls(particles, materials, walls, facets, contact_law=str(d["contact_law"]),
                     gravity=d["gravity"], dt=dt, safety_factor=safety, local_damping=local,
                     viscous_damping=viscous, skin=float(d["nl_skin"]), comm=comm, clumps=clumps)
        engine._wall_points_known = d["wall_point_known"].reshape(-1, 3).copy()
        for k in range(len(facets)):
            engine._facet_vertices_known[engine.facet_rows(k)] = d[f"facet{k}_vertices_known"]
        serial_lists = "nl_perm" in d
        if serial_lists and comm is None:
            engine.neighbors.set_state({k[3:]: v for k, v in d.items() if k.startswith("nl_")})
            engine.facet_active = np.zeros(engine.neighbors.f_tri.size, np.bool_)
            for name in ("j_rec", "pair_ov", "facet_force", "facet_lambda"):
                setattr(engine, name, d[name].copy())
        elif serial_lists:  # a serial checkpoint resumed over ranks: its history as records
            lists = NeighborList(float(d["nl_skin"]))
            lists.rolling = engine.neighbors.rolling
            lists.set_state({k[3:]: v for k, v in d.items() if k.startswith("nl_")})
            engine._pending_records = lists.records()
        elif "records_pair_keys" in d:
            engine._pending_records = ContactRecords(**{k: d[f"records_{k}"] for k in ContactRecords._fields})
        books = d["energy_books"].copy()
        jump = float(d["energy_jump"])
        if engine.domain is None:
            engine.acceleration = d["acceleration"].copy()
        else:
            engine.acceleration = d["acceleration"][engine.domain.ids].copy()
            if not engine.runner.is_root:  # the totals live on the root; the others start their sums from zero
                flag = books[BOOK_INITIALISED]
                books[:] = 0.0
                books[BOOK_INITIALISED] = flag
                jump = 0.0
        engine.time = float(time)
        engine.step_count = int(d["step_count"])
        engine._books = books
        engine._jump_work = jump
        return engine
