"""The explicit FE step of :mod:`fe_domain.explicit` as compiled loops (Numba).

The step is the same arithmetic as ``ExplicitSolid``'s PETSc path (docs/design.md §4.4,
steps 1–4): six sparse matrix–vector products with the operators assembled once, and nodal
array operations. On one rank every node is owned and there is nothing to scatter, so the
whole step can run in one compiled call: ≈ 25 Python-level calls a step (PETSc products,
NumPy operations) become two (or one call for many steps, :func:`steps`), and the FE–DE
coupling calls it from inside its own compiled loop (:mod:`cosim.compiled_coupling`).

On several ranks the operators hold the **owned rows** of the assembled matrices, with
their columns in the rank's local node numbering (owned, then ghost nodes; the mesh
partitioner ghosts every cell around an owned node, :func:`fe_domain.mesh.reproducible_partitioner`,
so every column is local), plus the owned rows of the transposes B and Pᵀ. The kernels
compute the owned rows; ``ExplicitSolid`` updates the ghosts between them (v and π after
the velocity update, p after the pressure update: DOLFINx's forward scatter) and u follows
on every local node from u += Δt v, the owner's arithmetic. The
operators share one node adjacency (``StepOperators``: each node pair holds its 3 × 3 block
of K, its 3 × 1 blocks of Bᵀ and P and its entry of L), so a step reads the adjacency twice
and each value once or twice: :func:`_internal_force` gathers K u + Bᵀ p and P p along the
rows in one pass, :func:`_pressure_terms` the transposes B v and Pᵀ π by adding each row's
blocks into its neighbours (and L p along the row) in another. That is ≈ 40 % less memory
than the six separate products (≈ 4.9 MB against 8.3 MB for 3,157 nodes), which matters
when the FE shares the cache with a DEM window. The results agree with PETSc's to
round-off, not to the bit (``tests/fe/test_fe_compiled_step.py``): the sums are taken in
another order.

A step is split where ``ExplicitSolid`` records its energies (between the velocity update
and the displacement update):

* :func:`velocity_update` — f_int = K_dev u + Bᵀ p, π = −G̃⁻¹ P p, f_ext = f_a + Σ a_l(t) F_l,
  F = f_ext − f_int − f_damp, v^{n+½} = v^{n−½} + Δt M⁻¹ F, supports;
* :func:`displacement_update` — u^{n+1} = u^n + Δt v^{n+½}, p^{n+1} = p^n + M_p⁻¹ [Δt B v^{n+½}
  − (L p^n + Pᵀ π^n)], and the work accumulators.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

DAMPING_NONE, DAMPING_MASS_PROPORTIONAL, DAMPING_LOCAL = 0, 1, 2
WORK_EXTERNAL, WORK_DAMPING, WORK_STABILISATION = 0, 1, 2


class StepOperators(NamedTuple):
    """The assembled step operators (explicit.py module docstring) on one node adjacency:
    row a lists the nodes j that share an element with a (``indices[indptr[a]:indptr[a+1]]``,
    ascending), and entry k of the row holds the node pair's block of each operator. The
    pure-displacement form has only ``stiffness`` (K); its other arrays are empty."""

    indptr: np.ndarray       # (n + 1,) int64
    indices: np.ndarray      # (entries,) int32
    stiffness: np.ndarray    # (entries, 3, 3): K_dev (mixed) or K, rows 3a+d, columns 3j+e
    divergence: np.ndarray   # (entries, 3): Bᵀ = ∫ N div N, row 3a+d, column j
    projection: np.ndarray   # (entries, 3): P = ∫ τ N·∇N, row 3a+d, column j
    laplacian: np.ndarray    # (entries,): L = ∫ τ ∇N·∇N
    divergence_t: np.ndarray  # (entries, 3): B = (Bᵀ)ᵀ, row a, columns 3j+d (several ranks; else empty)
    projection_t: np.ndarray  # (entries, 3): Pᵀ, row a, columns 3j+d (several ranks; else empty)


class NodalArrays(NamedTuple):
    """The solid's nodal arrays, flat (3 components per node for vectors), shared with
    ``ExplicitSolid`` (the same memory)."""

    displacement: np.ndarray
    velocity: np.ndarray
    pressure: np.ndarray
    projected_gradient: np.ndarray     # π
    external_force: np.ndarray         # f_a, e.g. the DEM interface forces
    loads: np.ndarray                  # (n_loads, 3n): F_l, each times its amplitude a_l(t)
    f_ext: np.ndarray
    f_int: np.ndarray
    net_force: np.ndarray
    damping_force: np.ndarray
    velocity_old: np.ndarray
    velocity_change: np.ndarray
    increment: np.ndarray
    mass: np.ndarray                   # M (lumped), 3n
    inverse_mass: np.ndarray           # 1 / M, 3n
    inverse_pressure_mass: np.ndarray  # 1 / M_p, n
    inverse_projection_mass: np.ndarray  # 1 / G̃ (0 where G̃ = 0), n
    projected: np.ndarray              # P p, 3n
    volumetric: np.ndarray             # B v, n
    stabilisation: np.ndarray          # L p + Pᵀ π, n
    fixed_dofs: np.ndarray             # int64
    prescribed_dofs: np.ndarray        # int64: dofs with a prescribed velocity ...
    prescribed_values: np.ndarray      # ... its value at amplitude 1 ...
    prescribed_group: np.ndarray       # ... and the condition (amplitude) it belongs to
    work: np.ndarray                   # WORK_*: Σ f_ext·Δu, Σ f_damp·Δu, Σ (p + ½Δp)·(L p + Pᵀ π)


class StepSettings(NamedTuple):
    dt: float
    mixed: bool
    damping: int          # DAMPING_*
    damping_alpha: float


def scipy_matrix(matrix, index_map):
    """The owned rows of an assembled PETSc matrix (AIJ or BAIJ) as a scipy CSR matrix whose
    columns are local: node columns (block size b = columns per node) numbered by
    ``index_map``, owned nodes then ghosts (on one rank: the matrix itself)."""
    from scipy.sparse import csr_matrix

    if "baij" in matrix.getType():
        from petsc4py import PETSc

        matrix = matrix.convert("aij", PETSc.Mat())  # into a new matrix (without one, petsc4py converts in place)
    indptr, indices, data = matrix.getValuesCSR()
    block = matrix.getSize()[1] // index_map.size_global
    node = local_nodes(index_map, indices // block)
    n_local = index_map.size_local + index_map.num_ghosts
    return csr_matrix((data.copy(), node * block + indices % block, indptr),
                      shape=(matrix.getLocalSize()[0], n_local * block))


def local_nodes(index_map, global_nodes):
    """Local indices (owned, then ghosts in ``index_map.ghosts`` order) of ``global_nodes``;
    a node that is not on the rank is an error (the mesh is not ghosted around its owned nodes)."""
    start, stop = index_map.local_range
    ghosts = np.asarray(index_map.ghosts, np.int64)
    owned = (global_nodes >= start) & (global_nodes < stop)
    local = global_nodes - start
    is_ghost = np.zeros_like(owned)
    if ghosts.size:
        order = np.argsort(ghosts)
        k = order[np.minimum(np.searchsorted(ghosts, global_nodes, sorter=order), ghosts.size - 1)]
        is_ghost = ~owned & (ghosts[k] == global_nodes)
        local = np.where(is_ghost, index_map.size_local + k, local)
    if not np.all(owned | is_ghost):
        raise RuntimeError(f"{int(np.sum(~(owned | is_ghost)))} operator columns are neither owned nor ghosts on "
                           "this rank: the mesh must ghost every cell around an owned node")
    return local


def step_operators(n_rows, n_nodes, stiffness, divergence=None, projection=None, laplacian=None,
                   divergence_t=None, projection_t=None) -> StepOperators:
    """The scipy matrices K (3r × 3n), Bᵀ, P (3r × n) and L (r × n), and on several ranks B and
    Pᵀ (r × 3n), of ``n_rows`` rows (r: owned nodes) over ``n_nodes`` local nodes, on their
    common node adjacency (the union of their patterns; for P1 operators of one mesh they are
    equal)."""
    from scipy.sparse import csr_matrix

    # (matrix, its block per node pair, the shape an entry stores)
    operators = [(stiffness, (3, 3), (3, 3)), (divergence, (3, 1), (3,)), (projection, (3, 1), (3,)),
                 (laplacian, (1, 1), ()), (divergence_t, (1, 3), (3,)), (projection_t, (1, 3), (3,))]
    converted = [(None if matrix is None else matrix.tobsr(blocksize=block), shape)
                 for matrix, block, shape in operators]
    pattern = sum(csr_matrix((np.ones(b.indices.size), b.indices, b.indptr), shape=(n_rows, n_nodes))
                  for b, _ in converted if b is not None).tocsr()
    pattern.sort_indices()
    rows = np.repeat(np.arange(n_rows), np.diff(pattern.indptr))
    keys = rows * n_nodes + pattern.indices               # ascending: rows, then columns
    values = []
    for bsr, shape in converted:
        if bsr is None:
            values.append(np.zeros((0, *shape)))
            continue
        bsr.sort_indices()
        own = np.repeat(np.arange(n_rows), np.diff(bsr.indptr)) * n_nodes + bsr.indices
        value = np.zeros((keys.size, *shape))
        value[np.searchsorted(keys, own)] = bsr.data.reshape(-1, *shape)
        values.append(value)
    return StepOperators(pattern.indptr.astype(np.int64), pattern.indices.astype(np.int32), *values)


@njit(cache=True, error_model="numpy")
def _internal_force(settings, ops, nodal):
    """f_int = K u (+ Bᵀ p), and P p into ``nodal.projected`` (mixed): one pass over the rows,
    one sum per row of each block (the three rows of a node add independently)."""
    u, p, f_int, projected = nodal.displacement, nodal.pressure, nodal.f_int, nodal.projected
    for a in range(ops.indptr.size - 1):
        f0 = f1 = f2 = 0.0
        q0 = q1 = q2 = 0.0
        for k in range(ops.indptr[a], ops.indptr[a + 1]):
            j = ops.indices[k]
            x0, x1, x2 = u[3 * j], u[3 * j + 1], u[3 * j + 2]
            block = ops.stiffness[k]
            f0 += block[0, 0] * x0 + block[0, 1] * x1 + block[0, 2] * x2
            f1 += block[1, 0] * x0 + block[1, 1] * x1 + block[1, 2] * x2
            f2 += block[2, 0] * x0 + block[2, 1] * x1 + block[2, 2] * x2
            if settings.mixed:
                pj = p[j]
                f0 += ops.divergence[k, 0] * pj
                f1 += ops.divergence[k, 1] * pj
                f2 += ops.divergence[k, 2] * pj
                q0 += ops.projection[k, 0] * pj
                q1 += ops.projection[k, 1] * pj
                q2 += ops.projection[k, 2] * pj
        f_int[3 * a], f_int[3 * a + 1], f_int[3 * a + 2] = f0, f1, f2
        if settings.mixed:
            projected[3 * a], projected[3 * a + 1], projected[3 * a + 2] = q0, q1, q2


@njit(cache=True, error_model="numpy")
def _pressure_terms(ops, nodal):
    """B v = (Bᵀ)ᵀ v into ``nodal.volumetric`` and L p + Pᵀ π into ``nodal.stabilisation``:
    one pass over the rows j; on one rank the transposes add row j's blocks into the entries
    of its neighbours a (in row order), on several (owned rows only, whose neighbours may be
    ghosts) they are gathered along row j from their own blocks; L p is gathered along row j."""
    v, p, pi = nodal.velocity, nodal.pressure, nodal.projected_gradient
    volumetric, stabilisation = nodal.volumetric, nodal.stabilisation
    if ops.divergence_t.shape[0]:
        for a in range(ops.indptr.size - 1):
            b_v = 0.0
            stab = 0.0
            for k in range(ops.indptr[a], ops.indptr[a + 1]):
                j = ops.indices[k]
                b_v += ops.divergence_t[k, 0] * v[3 * j] + ops.divergence_t[k, 1] * v[3 * j + 1] + \
                    ops.divergence_t[k, 2] * v[3 * j + 2]
                stab += ops.projection_t[k, 0] * pi[3 * j] + ops.projection_t[k, 1] * pi[3 * j + 1] + \
                    ops.projection_t[k, 2] * pi[3 * j + 2] + ops.laplacian[k] * p[j]
            volumetric[a] = b_v
            stabilisation[a] = stab
        return
    volumetric[:] = 0.0
    stabilisation[:] = 0.0
    for j in range(ops.indptr.size - 1):
        v0, v1, v2 = v[3 * j], v[3 * j + 1], v[3 * j + 2]
        w0, w1, w2 = pi[3 * j], pi[3 * j + 1], pi[3 * j + 2]
        laplacian = 0.0
        for k in range(ops.indptr[j], ops.indptr[j + 1]):
            a = ops.indices[k]
            volumetric[a] += ops.divergence[k, 0] * v0 + ops.divergence[k, 1] * v1 + ops.divergence[k, 2] * v2
            stabilisation[a] += ops.projection[k, 0] * w0 + ops.projection[k, 1] * w1 + ops.projection[k, 2] * w2
            laplacian += ops.laplacian[k] * p[a]
        stabilisation[j] += laplacian


@njit(cache=True, error_model="numpy")
def velocity_update(settings, ops, nodal, load_amplitudes, prescribed_amplitudes):
    """docs/design.md §4.4 step 1 (and step 4 for π^n): the arrays of ``nodal`` from u^n, p^n,
    v^{n−½} to v^{n+½}; ``load_amplitudes`` a_l(tⁿ), ``prescribed_amplitudes`` at t^{n+½}."""
    dt = settings.dt
    rows = ops.indptr.size - 1  # the owned nodes (all on one rank)
    _internal_force(settings, ops, nodal)
    if settings.mixed:
        for a in range(rows):
            for d in range(3):
                nodal.projected_gradient[3 * a + d] = nodal.projected[3 * a + d] * -nodal.inverse_projection_mass[a]
    f_ext = nodal.f_ext
    for i in range(3 * rows):
        value = nodal.external_force[i]
        for m in range(load_amplitudes.size):
            value += load_amplitudes[m] * nodal.loads[m, i]
        f_ext[i] = value
        nodal.net_force[i] = value - nodal.f_int[i]
    velocity = nodal.velocity
    for i in range(3 * rows):
        if settings.damping == DAMPING_MASS_PROPORTIONAL:
            f_damp = settings.damping_alpha * nodal.mass[i] * velocity[i]
        elif settings.damping == DAMPING_LOCAL:
            f_damp = settings.damping_alpha * abs(nodal.net_force[i]) * np.sign(velocity[i])
        else:
            f_damp = 0.0
        nodal.damping_force[i] = f_damp
        nodal.net_force[i] -= f_damp
        nodal.velocity_old[i] = velocity[i]
        velocity[i] += dt * nodal.inverse_mass[i] * nodal.net_force[i]
    for dof in nodal.fixed_dofs:
        velocity[dof] = 0.0
    for k in range(nodal.prescribed_dofs.size):
        velocity[nodal.prescribed_dofs[k]] = prescribed_amplitudes[nodal.prescribed_group[k]] * \
            nodal.prescribed_values[k]
    for i in range(3 * rows):
        nodal.velocity_change[i] = velocity[i] - nodal.velocity_old[i]


@njit(cache=True, error_model="numpy")
def displacement_update(settings, ops, nodal):
    """docs/design.md §4.4 steps 2–3: u^{n+1} (every local node: v's ghosts are current),
    p^{n+1} (owned nodes), and the work accumulators (owned nodes)."""
    dt = settings.dt
    rows = ops.indptr.size - 1
    work = nodal.work
    external = 0.0
    damping = 0.0
    for i in range(nodal.displacement.size):
        increment = dt * nodal.velocity[i]
        nodal.increment[i] = increment
        if i < 3 * rows:
            external += nodal.f_ext[i] * increment
            damping += nodal.damping_force[i] * increment
        nodal.displacement[i] += increment
    work[WORK_EXTERNAL] += external
    work[WORK_DAMPING] += damping
    if settings.mixed:
        _pressure_terms(ops, nodal)
        dissipation = 0.0
        for a in range(rows):
            change = (dt * nodal.volumetric[a] - nodal.stabilisation[a]) * nodal.inverse_pressure_mass[a]
            dissipation += (nodal.pressure[a] + 0.5 * change) * nodal.stabilisation[a]
            nodal.pressure[a] += change
        work[WORK_STABILISATION] += dissipation


@njit(cache=True, error_model="numpy")
def steps(settings, ops, nodal, load_amplitudes, prescribed_amplitudes):
    """Whole steps, one per row of the amplitude arrays (no energy record in between)."""
    for s in range(load_amplitudes.shape[0]):
        velocity_update(settings, ops, nodal, load_amplitudes[s], prescribed_amplitudes[s])
        displacement_update(settings, ops, nodal)
