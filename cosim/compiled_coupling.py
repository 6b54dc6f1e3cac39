"""The coupling schedule (docs/design.md §5.3) for many FE steps in one compiled call, on one
MPI rank; on several, each FE step with its interface motion in one compiled call.

Per FE step the schedule is: the FE step, the interface vertices set from the FE state, a
DEM window of ``subcycles`` steps, the window's impulse handed to the FE. Done from Python
(:func:`cosim.apps.coupled.coupled_step`) that is ≈ 30 calls a step, and the DEM window's
entry into its compiled kernel unboxes ≈ 60 arrays: with one substep the Python work and
the entries cost ≈ 100 µs a step, a third of a 3,000-grain DEM step (README, "Coupling
overhead"). :func:`coupled_steps` runs the same schedule for up to ``n_fe`` FE steps inside
one compiled function: the FE step of :mod:`fe_domain.compiled`, the interface loops below,
and :func:`de_domain.fused.advance` for each window — with the same arithmetic in the same
order, so a run is bit-identical to the step-by-step one (``tests/coupling/
test_compiled_coupling.py``).

The compiled loop returns to Python when the DEM lists must be rebuilt, before or inside a
window (the build is Python); :class:`CoupledStepper` then finishes that window, and the
next FE step, the way the step-by-step schedule does, so that a rebuild happens at the same
instant with the same vertex positions.

On several ranks the DEM steps from Python (its ghost exchange and facet force gather between
the steps, :mod:`de_domain.distributed`). With the FE replicated on every rank
(``coupling.fe_partition``), the last window's interface forces, the FE step and the interface
motion are one compiled call, :func:`fe_step_and_motion`, instead of ≈ 10 calls from Python
(≈ 60 µs a step), entered without typing or checking its arguments after the first FE step
of a :meth:`CoupledStepper.run` (:attr:`numba_support.dispatch.CachedEntry.entry`).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from de_domain.fused import advance
from de_domain.neighbors import moved_beyond_skin
from de_domain.state import CLOCK_PARTICLE_SHIFT, CLOCK_STEPS
from fe_domain.compiled import displacement_update, velocity_update
from numba_support.dispatch import CachedEntry

#: Slots of the status array :func:`coupled_steps` fills.
DONE_FE_STEPS = 0     # FE steps whose window and interface forces are complete
OPEN_WINDOW = 1       # 1: one more FE step is done, its window stopped for a list rebuild ...
OPEN_WINDOW_STEPS = 2  # ... after this many DEM steps
REBUILD_DUE = 3       # 1: the lists must be rebuilt before the next window


class FeSteps(NamedTuple):
    """The FE solid's compiled step (:meth:`fe_domain.explicit.ExplicitSolid.compiled_arguments`)
    and the amplitudes of its loads and prescribed velocities for each FE step of the call."""

    settings: tuple
    operators: tuple
    nodal: tuple
    load_amplitudes: np.ndarray        # (n_fe, n_loads) at tⁿ
    prescribed_amplitudes: np.ndarray  # (n_fe, n_conditions) at t^{n+½}


class InterfaceArrays(NamedTuple):
    """The interface (:class:`cosim.interface.Interface`) on one rank."""

    node: np.ndarray          # (m,) FE node of each interface vertex
    reference: np.ndarray     # (m, 3) reference position X of each vertex's FE node, in vertex order
    first_row: int            # row of vertex 0 in the DEM's concatenated facet arrays
    held: np.ndarray          # (m, 3) impulse held back by the smoothing
    held_before: np.ndarray   # (m, 3) ... before the last window's joined it
    released: np.ndarray      # (m, 3) impulse handed to the next FE step
    smoothing: bool
    release_fraction: float   # β (1 without smoothing)
    jump_work: np.ndarray     # (1,) the DEM's boundary jump work, booked window by window
    window_impulse: np.ndarray  # (3,) Σ over the windows of the impulse the grains gave the interface


@njit(cache=True, error_model="numpy")
def _start_position(fe, interface, k, a, d):
    """Coordinate d of interface vertex k, at FE node a, at the start of the window,
    X + u^n = X + (u^{n+1} − Δt v^{n+½}). X is read in vertex order (``interface.reference``, a
    copy made once): gathering it by node from the FE's coordinates, which no FE step reads and
    which are out of cache by then, cost a cache miss a vertex (≈ 20 µs a step at 1,507 vertices;
    docs/performance.md)."""
    nodal = fe.nodal
    return interface.reference[k, d] + (nodal.displacement[3 * a + d] - fe.settings.dt * nodal.velocity[3 * a + d])


@njit(cache=True, error_model="numpy")
def _send_motion(fe, interface, meshes):
    """§5.3 step 2: the vertices start at X + u^n and move with v^{n+½}; the jump from where the
    DEM left them is booked as boundary work; the impulse starts at zero."""
    v = fe.nodal.velocity
    vertices, velocity, impulse, force = meshes.vertices, meshes.vertex_velocity, meshes.vertex_impulse, \
        meshes.vertex_force
    work = 0.0
    for k in range(interface.node.size):
        a = interface.node[k]
        r = interface.first_row + k
        for d in range(3):
            x = _start_position(fe, interface, k, a, d)
            work -= force[r, d] * (x - vertices[r, d])
            vertices[r, d] = x
            velocity[r, d] = v[3 * a + d]
            impulse[r, d] = 0.0
    interface.jump_work[0] += work


@njit(cache=True, error_model="numpy")
def _receive_forces(fe, interface, impulse):
    """§5.3 step 4: the interface force of the next FE step = released impulse / Δt_FE
    (with smoothing, released = β (held + window's impulse), the rest held); the window's
    impulse (rows ``interface.first_row`` … of ``impulse``) added to ``window_impulse``
    (summed over the vertices first, in their order)."""
    window = fe.settings.dt
    external = fe.nodal.external_force
    total_impulse = np.zeros(3)
    for k in range(interface.node.size):
        a = interface.node[k]
        r = interface.first_row + k
        for d in range(3):
            total_impulse[d] += impulse[r, d]
            if interface.smoothing:
                interface.held_before[k, d] = interface.held[k, d]
                total = interface.held[k, d] + impulse[r, d]
                interface.released[k, d] = interface.release_fraction * total
                interface.held[k, d] = total - interface.released[k, d]
            else:
                interface.released[k, d] = impulse[r, d]
            external[3 * a + d] = interface.released[k, d] / window
    for d in range(3):
        interface.window_impulse[d] += total_impulse[d]


@njit(cache=True, error_model="numpy")
def fe_step_and_motion(step, fe, interface, vertices, vertex_velocity, vertex_impulse, window_done):
    """With ``window_done``, first §5.3 step 4 for the last window (:func:`_receive_forces`, on
    the impulse in the interface facet mesh's own arrays, ``interface.first_row`` = 0); then the
    FE step with the amplitudes of row ``step`` of ``fe`` (:class:`FeSteps`) and §5.3 step 2 on
    those arrays, vertex k at FE node ``interface.node[k]``: at X + u^n, moving with v^{n+½},
    no impulse yet (the DEM's run books the vertices' jump)."""
    if window_done:
        _receive_forces(fe, interface, vertex_impulse)
    velocity_update(fe.settings, fe.operators, fe.nodal, fe.load_amplitudes[step], fe.prescribed_amplitudes[step])
    displacement_update(fe.settings, fe.operators, fe.nodal)
    v = fe.nodal.velocity
    for k in range(interface.node.size):
        a = interface.node[k]
        for d in range(3):
            vertices[k, d] = _start_position(fe, interface, k, a, d)
            vertex_velocity[k, d] = v[3 * a + d]
            vertex_impulse[k, d] = 0.0


@njit(cache=True, error_model="numpy")
def _rebuild_due(settings, particles, walls, meshes, clock):
    """The engine's test before a run (``NeighborList.needs_rebuild`` on the sorted copies,
    with the particles' largest displacement from the last step if there was one)."""
    return moved_beyond_skin(clock[CLOCK_PARTICLE_SHIFT], particles.pos, particles.ref_pos, particles.pos.shape[0],
                             meshes.vertices, meshes.ref_vertices, walls.point, walls.ref_point, settings.skin)


@njit(cache=True, error_model="numpy")
def coupled_steps(n_fe, subcycles, fe, interface, dem, books, clock, status):
    """Up to ``n_fe`` FE steps of the schedule; ``dem``: the eight named tuples of
    :func:`de_domain.fused.advance`. Fills ``status`` (slots ``DONE_FE_STEPS`` …) and
    returns the DEM steps done."""
    settings, particles, params, pairs, walls, meshes, candidates, clumps = dem
    status[:] = 0
    dem_steps = 0
    for s in range(n_fe):
        velocity_update(fe.settings, fe.operators, fe.nodal, fe.load_amplitudes[s], fe.prescribed_amplitudes[s])
        displacement_update(fe.settings, fe.operators, fe.nodal)
        _send_motion(fe, interface, meshes)
        if _rebuild_due(settings, particles, walls, meshes, clock):
            status[OPEN_WINDOW] = 1
            return dem_steps
        clock[CLOCK_STEPS] = 0.0
        due = advance(subcycles, settings, particles, params, pairs, walls, meshes, candidates, clumps, books, clock)
        done = int(clock[CLOCK_STEPS])
        dem_steps += done
        if done < subcycles:
            status[OPEN_WINDOW] = 1
            status[OPEN_WINDOW_STEPS] = done
            return dem_steps
        _receive_forces(fe, interface, meshes.vertex_impulse)
        status[DONE_FE_STEPS] = s + 1
        if due:
            status[REBUILD_DUE] = 1
            return dem_steps
    return dem_steps


class CoupledStepper:
    """FE steps of the coupling schedule: in compiled calls (:func:`coupled_steps`) when the
    FE solid steps compiled and the DEM engine is serial (one rank); with a distributed engine
    and the whole FE on this rank, each FE step and its interface motion in one compiled call
    (:func:`fe_step_and_motion`); else step by step (``step_by_step``). Bit-identical all ways."""

    def __init__(self, solid, engine, interface, subcycles):
        self.solid, self.engine, self.interface, self.subcycles = solid, engine, interface, int(subcycles)
        rows = [engine.facet_rows(k) for k, mesh in enumerate(engine.facets) if mesh is interface.facets]
        local_fe = solid.compiled_arguments() is not None
        self.compiled = local_fe and engine.domain is None and len(rows) == 1
        self.fe_compiled = local_fe and engine.domain is not None  # the DEM steps from Python
        self._fe_step = CachedEntry(fe_step_and_motion)
        self._python_step_next = True  # the first window (lists built, gathered) goes step by step
        self._status = np.zeros(4, np.int64)
        # the compiled call's arguments are the same array objects call after call (amplitude
        # rows for up to ``_capacity`` FE steps): CachedEntry then skips Numba's typing of its
        # ≈ 150 arrays, ≈ 0.5 ms a call
        self._kernel = CachedEntry(coupled_steps)
        self._capacity = 0
        self._amplitudes = None
        self._jump = np.zeros(1)
        #: Σ of the windows' interface impulses (N s) since the caller last zeroed it
        self.window_impulse = np.zeros(3)
        self.fe_steps_compiled = 0        # FE steps done in compiled calls ...
        self.windows_finished = 0         # ... of which windows stopped for a rebuild, finished from Python
        if self.compiled:
            self._first_row = rows[0].start
        if local_fe:  # every node owned
            self._vertex_node = np.empty(len(interface.facets.vertices), np.int64)
            self._vertex_node[interface.owned_vertices] = interface.owned_nodes
            self._vertex_reference = np.ascontiguousarray(solid.node_coordinates[self._vertex_node])

    def run(self, count, step_by_step):
        """``count`` FE steps; ``step_by_step(solid, engine, interface, subcycles)`` is one FE step
        and its window from Python (:func:`cosim.apps.coupled.coupled_step`)."""
        done = 0
        while done < count:
            if self.fe_compiled and not self.solid.energy_due():
                done += self._fe_compiled_steps(count - done)
                continue
            started = None
            if self.compiled and not self._python_step_next and not self.solid.energy_due() and \
                    self.engine.steps_before_reorder() >= self.subcycles:
                started = self.engine.start_external_run()  # None: the lists are due for a rebuild
            if started is None:
                step_by_step(self.solid, self.engine, self.interface, self.subcycles)
                self.window_impulse += self.interface.facets.vertex_impulse.sum(axis=0)
                self._python_step_next = False
                done += 1
            else:
                done += self._compiled_steps(count - done, started)

    def _amplitude_rows(self, count):
        """:class:`FeSteps` with the amplitudes of the next ``count`` FE steps, in arrays kept
        from call to call (see ``_kernel``)."""
        solid = self.solid
        if count > self._capacity:
            self._capacity = max(count, 64)
            self._amplitudes = solid.compiled_amplitudes(self._capacity)
        return FeSteps(*solid.compiled_arguments(), *solid.compiled_amplitudes(count, *self._amplitudes))

    def _fe_compiled_steps(self, count):
        """Up to ``count`` FE steps (until the next FE energy record), each in one
        :func:`fe_step_and_motion` call, then its window on the distributed DEM and the
        interface forces from Python. Returns the FE steps done."""
        solid, engine, interface = self.solid, self.engine, self.interface
        if solid.energy_interval > 0:
            count = min(count, solid.energy_interval - solid.step_count % solid.energy_interval)
        fe = self._amplitude_rows(count)
        arrays = self._interface_arrays(0)  # the interface facet mesh's own rows
        facets = interface.facets
        motion = (facets.vertices, facets.vertex_velocity, facets.vertex_impulse)
        from cosim.apps import dem as dem_app
        for step in range(count):
            if step == 0:  # the last window's forces are received already
                self._fe_step(step, fe, arrays, *motion, False)
            else:  # the last window's forces first; the argument objects of the call before: its entry point
                self._fe_step.entry(step, fe, arrays, *motion, True)
            solid.finish_compiled_steps(1)
            dem_app.advance(engine, self.subcycles)
        interface.receive_forces(solid.dt)  # the last window's (then an output may read them)
        self.window_impulse += facets.vertex_impulse.sum(axis=0)
        self.fe_steps_compiled += count
        return count

    def _interface_arrays(self, first_row):
        """:class:`InterfaceArrays` over the interface's arrays, its vertex 0 at row ``first_row``
        of the facet arrays the kernels get."""
        solid, interface = self.solid, self.interface
        return InterfaceArrays(self._vertex_node, self._vertex_reference, first_row, interface.held,
                               interface.held_before, interface.released, interface.smoothing_time > 0.0,
                               interface.release_fraction(solid.dt), self._jump, self.window_impulse)

    def _compiled_steps(self, count, started):
        """Up to ``count`` FE steps in one :func:`coupled_steps` call (fewer when the lists
        must be rebuilt, the spatial order refreshed or the FE energies recorded first);
        ``started``: :meth:`de_domain.Engine.start_external_run`. Returns the FE steps done."""
        solid, engine, interface, n_sub = self.solid, self.engine, self.interface, self.subcycles
        count = min(count, engine.steps_before_reorder() // n_sub)
        if solid.energy_interval > 0:
            count = min(count, solid.energy_interval - solid.step_count % solid.energy_interval)
        fe = self._amplitude_rows(count)
        dem, books, clock = started
        self._jump[0] = engine.boundary_jump_work
        arrays = self._interface_arrays(self._first_row)
        status = self._status
        dem_steps = self._kernel(count, n_sub, fe, arrays, dem, books, clock, status)
        engine.end_external_run(dem_steps, self._jump[0])
        fe_steps = int(status[DONE_FE_STEPS] + status[OPEN_WINDOW])
        solid.finish_compiled_steps(fe_steps)
        self.fe_steps_compiled += fe_steps
        if status[OPEN_WINDOW]:  # the window's rest, and the interface forces, as step by step
            self.windows_finished += 1
            from cosim.apps import dem as dem_app
            dem_app.advance(engine, n_sub - int(status[OPEN_WINDOW_STEPS]))
            interface.receive_forces(solid.dt)
            self.window_impulse += interface.facets.vertex_impulse.sum(axis=0)
        self._python_step_next = bool(status[REBUILD_DUE] or status[OPEN_WINDOW])
        return fe_steps
