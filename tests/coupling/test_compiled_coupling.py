"""The coupling schedule in compiled calls (cosim/compiled_coupling.py) is the step-by-step
one, bit for bit: FE state, particles, contact histories, interface forces, the impulse in
transit and held back, the energy books; with list rebuilds inside windows (windows finished
from Python), with 1 and several substeps, with the interface smoothing on, and with the
compiled run on two Numba threads."""

import numba
import numpy as np
import pytest

from cosim.apps import coupled
from cosim.case import load_case
from cosim.compiled_coupling import CoupledStepper
from tests.coupling.test_coupled_impact import impact_case

FE_STEPS = 600


def prepared(tmp_path, subcycles, smoothing):
    tmp_path.mkdir()
    path = impact_case(tmp_path, name=f"compiled_{subcycles}_{smoothing}", cloud_bottom=-0.002)
    overrides = [f"coupling.subcycles={subcycles}", f"coupling.smoothing_time={smoothing}",
                 "dem.particles.velocity=[0.0, 0.0, 1.5]"]  # the grains hit the plate within the steps
    case, _ = load_case(path, overrides)
    return coupled.prepare(case, path, tmp_path / "out", resume=False)


def state(built):
    solid, engine, interface = built["solid"], built["engine"], built["interface"]
    p = engine.particles
    nl = engine.neighbors
    return {"u": solid.displacement, "v": solid.velocity, "p": solid.pressure, "f": solid.external_force,
            "x": p.pos, "w": p.vel, "omega": p.angvel, "a": engine.acceleration, "ht": nl.ht,
            "facet_history": nl.facet_history, "released": interface.released, "held": interface.held,
            "impulse": interface.facets.vertex_impulse, "vertices": interface.facets.vertices,
            "books": engine._books, "clock": np.array([solid.time, engine.time, engine.boundary_jump_work]),
            "work": solid._work}


def run_steps(tmp_path, subcycles, smoothing, compiled):
    """FE_STEPS coupled steps, 20 a call: (state, stepper, list builds)."""
    built = prepared(tmp_path, subcycles, smoothing)
    stepper = CoupledStepper(built["solid"], built["engine"], built["interface"], built["subcycles"])
    assert stepper.compiled
    stepper.compiled = compiled
    builds = built["engine"].neighbors.n_builds
    for _ in range(FE_STEPS // 20):
        stepper.run(20, coupled.coupled_step)
    assert built["solid"].step_count == FE_STEPS
    return ({**state(built), "window_impulse": stepper.window_impulse}, stepper,
            built["engine"].neighbors.n_builds - builds)


@pytest.mark.parametrize("subcycles, smoothing, threads", [(1, 0.0, 1), (4, 0.0, 1), (3, 2e-4, 1), (3, 0.0, 2)])
def test_compiled_schedule_is_the_step_by_step_one_bit_for_bit(tmp_path, subcycles, smoothing, threads):
    """(``threads``: Numba threads of the compiled run; the step-by-step one has one.)"""
    runs = []
    try:
        for compiled in (True, False):
            numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS) if compiled else 1)
            runs.append(run_steps(tmp_path / str(compiled), subcycles, smoothing, compiled))
    finally:
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    (fast, stepper, builds), (reference, _, reference_builds) = runs
    assert stepper.fe_steps_compiled > FE_STEPS // 2       # most steps ran compiled ...
    assert builds > 5                                      # ... with list rebuilds,
    assert stepper.windows_finished > 0 or subcycles == 1  # inside windows too
    assert builds == reference_builds
    assert abs(fast["v"]).max() > 0.01  # the grains hit the plate (it has no other load)
    for key, value in reference.items():
        assert np.array_equal(fast[key], value, equal_nan=True), key


def test_the_coupling_kernels_are_cached_under_a_digest_of_the_domains_sources_too():
    """coupled_steps calls de_domain's and fe_domain's kernels: its cache must follow their sources."""
    from pathlib import Path

    import de_domain
    import fe_domain
    from cosim import compiled_coupling
    from numba_support import kernel_cache

    cosim_dir = Path(compiled_coupling.__file__).resolve().parent
    domains = [Path(de_domain.__file__).resolve().parent, Path(fe_domain.__file__).resolve().parent]
    digest = kernel_cache.DIGESTS[cosim_dir]
    assert digest == kernel_cache.source_digest(cosim_dir, domains) != kernel_cache.source_digest(cosim_dir)
    assert kernel_cache.cache_dir_name(digest) in compiled_coupling.coupled_steps._cache._cache_path


@pytest.mark.mpi
@pytest.mark.parametrize("subcycles, smoothing", [(1, 0.0), (3, 2e-4)])
def test_on_several_ranks_the_fe_steps_in_compiled_calls_are_the_step_by_step_ones_bit_for_bit(
        tmp_path_factory, subcycles, smoothing):
    """Under mpirun (the DEM distributed, the FE replicated on every rank): each FE step with the
    last window's interface forces (smoothed too) and its interface motion in one compiled call
    (``fe_step_and_motion``) gives the bits of the step-by-step schedule, on every rank, through
    list rebuilds."""
    from mpi4py import MPI
    comm = MPI.COMM_WORLD
    assert comm.size > 1
    folder = tmp_path_factory.mktemp(f"several_{subcycles}_{smoothing}") if comm.rank == 0 else None
    folder = comm.bcast(folder, root=0)
    runs = []
    for fast in (True, False):
        built = prepared(folder / f"{fast}_{comm.rank}", subcycles, smoothing)
        stepper = CoupledStepper(built["solid"], built["engine"], built["interface"], built["subcycles"])
        assert stepper.fe_compiled and not stepper.compiled
        stepper.fe_compiled = fast
        builds = built["engine"].neighbors.n_builds
        for _ in range(FE_STEPS // 20):
            stepper.run(20, coupled.coupled_step)
        runs.append(({**state(built), "window_impulse": stepper.window_impulse}, stepper,
                     built["engine"].neighbors.n_builds - builds))
    (fast, stepper, builds), (reference, _, reference_builds) = runs
    assert stepper.fe_steps_compiled > FE_STEPS // 2 and builds > 5 and builds == reference_builds
    assert abs(fast["v"]).max() > 0.01  # the grains hit the plate
    for key, value in reference.items():
        assert np.array_equal(fast[key], value, equal_nan=True), key
