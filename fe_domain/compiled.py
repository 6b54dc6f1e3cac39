"""The explicit FE step of :mod:`fe_domain.explicit` as compiled loops (Numba), for one MPI rank.

The step is the same arithmetic as ``ExplicitSolid``'s PETSc path (docs/design.md §4.4,
steps 1–4): six sparse matrix–vector products with the operators assembled once, and nodal
array operations. On one rank every node is owned and there is nothing to scatter, so the
whole step can run in one compiled call: ≈ 25 Python-level calls a step (PETSc products,
NumPy operations) become two (or one call for many steps, :func:`steps`), and the FE–DE
coupling calls it from inside its own compiled loop (:mod:`cosim.compiled_coupling`). Each
operator is a CSR matrix (``BlockMatrix``); the transposes Bᵀᵀ = B and Pᵀ are stored as their
own CSR matrices, so every product is a row gather (:func:`_product`). The results agree
with PETSc's to round-off, not to the bit (``tests/fe/test_fe_compiled_step.py``): the sums
of a row are taken in another order.

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


class BlockMatrix(NamedTuple):
    """A sparse matrix of R × C blocks in compressed block rows (scipy's BSR): block row i
    holds the blocks ``data[indptr[i]:indptr[i+1]]`` (each R × C) at block columns
    ``indices[...]``. The operators are blocks per node pair: 3 × 3 (K), 3 × 1 (Bᵀ, P),
    1 × 3 (B, Pᵀ), 1 × 1 (L)."""

    indptr: np.ndarray
    indices: np.ndarray
    data: np.ndarray   # (blocks, R, C)


class StepOperators(NamedTuple):
    """The assembled step operators (explicit.py module docstring). The pure-displacement
    form has only ``stiffness`` (K); its other matrices are empty."""

    stiffness: BlockMatrix       # K_dev (mixed) or K, 3n × 3n
    divergence: BlockMatrix      # Bᵀ = ∫ N div N, 3n × n
    divergence_t: BlockMatrix    # B, n × 3n
    projection: BlockMatrix      # P = ∫ τ N·∇N, 3n × n
    projection_t: BlockMatrix    # Pᵀ, n × 3n
    laplacian: BlockMatrix       # L = ∫ τ ∇N·∇N, n × n


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


def scipy_matrix(matrix):
    """An assembled one-rank PETSc matrix (AIJ or BAIJ) as a scipy CSR matrix."""
    from scipy.sparse import csr_matrix

    if "baij" in matrix.getType():
        matrix = matrix.convert("aij")
    indptr, indices, data = matrix.getValuesCSR()
    return csr_matrix((data.copy(), indices, indptr), shape=matrix.getSize())


def blocks(matrix, rows, columns) -> BlockMatrix:
    """A scipy sparse matrix in ``rows`` × ``columns`` blocks (a node's components together;
    block entries outside the assembled pattern are zeros)."""
    bsr = matrix.tobsr(blocksize=(rows, columns))
    bsr.sort_indices()
    return BlockMatrix(bsr.indptr.astype(np.int64), bsr.indices.astype(np.int64), np.ascontiguousarray(bsr.data))


def empty_blocks() -> BlockMatrix:
    return BlockMatrix(np.zeros(1, np.int64), np.zeros(0, np.int64), np.zeros((0, 1, 1)))


@njit(cache=True, error_model="numpy")
def _product(a, x, y, add):
    """y = A x (``add``: y += A x) for blocks of 3 × 3, 3 × 1, 1 × 3 or 1 × 1. Per block row,
    over its blocks in column order: 3 × R blocks add each row's three products into that
    row's sum; 1 × 3 blocks keep one sum per component (added up at the end); 1 × 1 blocks
    alternate two sums. Independent sums, so the additions overlap in the CPU."""
    indptr, indices, data = a.indptr, a.indices, a.data
    rows, columns = data.shape[1], data.shape[2]
    for i in range(indptr.size - 1):
        start, end = indptr[i], indptr[i + 1]
        s0 = s1 = s2 = 0.0
        if rows == 3 and columns == 3:
            for k in range(start, end):
                j = indices[k]
                x0, x1, x2 = x[3 * j], x[3 * j + 1], x[3 * j + 2]
                s0 += data[k, 0, 0] * x0 + data[k, 0, 1] * x1 + data[k, 0, 2] * x2
                s1 += data[k, 1, 0] * x0 + data[k, 1, 1] * x1 + data[k, 1, 2] * x2
                s2 += data[k, 2, 0] * x0 + data[k, 2, 1] * x1 + data[k, 2, 2] * x2
        elif rows == 3:
            for k in range(start, end):
                xj = x[indices[k]]
                s0 += data[k, 0, 0] * xj
                s1 += data[k, 1, 0] * xj
                s2 += data[k, 2, 0] * xj
        elif columns == 3:
            for k in range(start, end):
                j = indices[k]
                s0 += data[k, 0, 0] * x[3 * j]
                s1 += data[k, 0, 1] * x[3 * j + 1]
                s2 += data[k, 0, 2] * x[3 * j + 2]
            s0 = (s0 + s1) + s2
        else:
            k = start
            while k + 1 < end:
                s0 += data[k, 0, 0] * x[indices[k]]
                s1 += data[k + 1, 0, 0] * x[indices[k + 1]]
                k += 2
            if k < end:
                s0 += data[k, 0, 0] * x[indices[k]]
            s0 += s1
        if rows == 3:
            if add:
                y[3 * i] += s0
                y[3 * i + 1] += s1
                y[3 * i + 2] += s2
            else:
                y[3 * i], y[3 * i + 1], y[3 * i + 2] = s0, s1, s2
        else:
            y[i] = y[i] + s0 if add else s0


@njit(cache=True, error_model="numpy")
def velocity_update(settings, ops, nodal, load_amplitudes, prescribed_amplitudes):
    """docs/design.md §4.4 step 1 (and step 4 for π^n): the arrays of ``nodal`` from u^n, p^n,
    v^{n−½} to v^{n+½}; ``load_amplitudes`` a_l(tⁿ), ``prescribed_amplitudes`` at t^{n+½}."""
    dt = settings.dt
    _product(ops.stiffness, nodal.displacement, nodal.f_int, False)
    if settings.mixed:
        _product(ops.divergence, nodal.pressure, nodal.f_int, True)
        _product(ops.projection, nodal.pressure, nodal.projected, False)
        for a in range(nodal.pressure.size):
            for d in range(3):
                nodal.projected_gradient[3 * a + d] = nodal.projected[3 * a + d] * -nodal.inverse_projection_mass[a]
    f_ext = nodal.f_ext
    for i in range(f_ext.size):
        value = nodal.external_force[i]
        for m in range(load_amplitudes.size):
            value += load_amplitudes[m] * nodal.loads[m, i]
        f_ext[i] = value
        nodal.net_force[i] = value - nodal.f_int[i]
    velocity = nodal.velocity
    for i in range(velocity.size):
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
    for i in range(velocity.size):
        nodal.velocity_change[i] = velocity[i] - nodal.velocity_old[i]


@njit(cache=True, error_model="numpy")
def displacement_update(settings, ops, nodal):
    """docs/design.md §4.4 steps 2–3: u^{n+1}, p^{n+1}, and the work accumulators."""
    dt = settings.dt
    work = nodal.work
    external = 0.0
    damping = 0.0
    for i in range(nodal.displacement.size):
        increment = dt * nodal.velocity[i]
        nodal.increment[i] = increment
        external += nodal.f_ext[i] * increment
        damping += nodal.damping_force[i] * increment
        nodal.displacement[i] += increment
    work[WORK_EXTERNAL] += external
    work[WORK_DAMPING] += damping
    if settings.mixed:
        _product(ops.divergence_t, nodal.velocity, nodal.volumetric, False)
        _product(ops.laplacian, nodal.pressure, nodal.stabilisation, False)
        _product(ops.projection_t, nodal.projected_gradient, nodal.stabilisation, True)
        dissipation = 0.0
        for a in range(nodal.pressure.size):
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
