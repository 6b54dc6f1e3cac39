"""The model the soil–structure kinds step (``embedded`` and its preset ``footing``; design §5, §7):
a DEM engine with its walls, rigid bodies and (coupled) the FE interface's facets, the FE
solid and the interface; its rest under gravity, and its checkpoints during the loading."""
from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np

from cosim.errors import CaseError
from cosim.outputs import (
    CsvSeries,
    atomic_write_text,
    commit_checkpoint,
    is_root,
    mpi_comm,
    save_engine_checkpoint,
    say,
    staged,
)

REST_COLUMNS = ["time", "interface_force_z", "grain_weight", "unbalanced_force_ratio"]
REST_CHECK_TIME = 2e-3  # s of simulated time between the rest checks


@dataclass
class Model:
    """A built model: the DEM engine (grains, walls, rigid bodies), and for the coupled one the
    FE solid and the interface (the engine's last facet mesh)."""
    engine: object
    solid: object = None
    interface: object = None
    subcycles: int = 1
    soil_density: float = None  # kg/m³ of the FE soil (coupled)
    stepper: object = None      # coupled: the FE steps (cosim.compiled_coupling.CoupledStepper)

    def __post_init__(self):
        # coupled: one DEM window per FE step, the sorted copies stay between windows
        self.engine.keep_sorted = self.solid is not None
        self.engine.wall_forces_each_run = self.solid is None  # coupled: nothing reads them between windows
        if self.solid is not None:
            from cosim.compiled_coupling import CoupledStepper
            self.stepper = CoupledStepper(self.solid, self.engine, self.interface, self.subcycles)

    @property
    def time(self):
        return self.engine.time

    def advance(self, seconds):
        """Advance by about ``seconds``: whole FE steps (coupled) or DEM steps."""
        from cosim.apps import coupled as coupled_app
        from cosim.apps import dem as dem_app
        if self.solid is None:
            dem_app.advance(self.engine, max(1, int(round(seconds / self.engine.dt))))
            return
        self.stepper.run(max(1, int(round(seconds / self.solid.dt))), coupled_app.coupled_step)

    def take_interface_impulse(self):
        """The impulse (N s) the grains gave the interface since the last call (0 for all-DEM)."""
        if self.stepper is None:
            return np.zeros(3)
        impulse = self.stepper.window_impulse.copy()
        self.stepper.window_impulse[:] = 0.0
        return impulse

    def interface_force(self):
        """Force (N) the grains exert on the interface over the last FE step (0 for all-DEM)."""
        if self.interface is None:
            return np.zeros(3)
        return self.interface.facets.vertex_impulse.sum(axis=0) / self.solid.dt

    def support_force(self):
        """Σ of the forces (N) the grains exerted on every wall and facet mesh (the interface's
        from its last FE step's impulse) over the last step; the same on every rank
        (collective: a model with an FE part does not total its plane walls' forces every
        window, so they are totalled here)."""
        self.engine.update_wall_forces()
        total = sum((w.force for w in self.engine.walls), np.zeros(3))
        for mesh in self.engine.facets:
            total = total + (self.interface_force() if self.interface is not None and mesh is self.interface.facets
                             else mesh.force)
        return total

    def grain_weight(self):
        """Σ m ``|g|`` of the grains (N; a clump's mass once), over all ranks (collective)."""
        from de_domain.diagnostics import total_mass
        return total_mass(self.engine) * float(np.linalg.norm(self.engine.gravity))


def unbalanced(model):
    """The grains' unbalanced force ratio (collective)."""
    from de_domain.diagnostics import unbalanced_force_ratio
    return unbalanced_force_ratio(model.engine)  # collective



def come_to_rest(model, out_dir, name, threshold, max_time):
    """Run under gravity until the unbalanced force ratio is below ``threshold`` (checked every
    REST_CHECK_TIME, for at most ``max_time`` s); ``rest.csv``; returns the balance at rest: the
    interface's vertical force, and every support's (walls, facets, interface) over the grains'
    weight. Collective."""
    weight = model.grain_weight()
    rows = CsvSeries(out_dir / "rest.csv", REST_COLUMNS) if is_root() else None
    start = model.time
    while True:
        model.advance(REST_CHECK_TIME)
        ufr = unbalanced(model)
        force = model.interface_force()
        if rows is not None:
            rows.append([model.time, force[2], weight, ufr])
        if ufr < threshold or model.time - start >= max_time:
            break
    if rows is not None:
        rows.close()
    force = model.interface_force()
    at_rest = bool(ufr < threshold)
    balance = -force[2] / weight if model.interface is not None else None
    supports = -model.support_force()[2] / weight
    say(f"[{name}] {'at rest' if at_rest else 'NOT at rest'} after {model.time - start:.3f} s: unbalanced force "
        f"ratio {ufr:.2e}" + (f", interface force / grain weight = {balance:.4f}" if balance is not None else "")
        + f", all supports' vertical force / grain weight = {supports:.4f}")
    return {"at_rest": at_rest, "rest_time": model.time - start, "unbalanced_force_ratio": ufr,
            "grain_weight_N": weight, "interface_force_z_N": float(force[2]),
            "interface_force_over_weight": balance, "support_force_over_weight": supports}


def save_checkpoint(out_dir, model, state, state_file):
    """The DEM (and, coupled, the FE with the impulse in transit: ``coupled.stage_checkpoint``)
    and the loading loop's ``state`` (JSON in ``state_file``, rank 0), committed together
    (:func:`cosim.outputs.commit_checkpoint`); collective."""
    from cosim.apps import coupled as coupled_app
    if model.solid is not None:
        finals = coupled_app.stage_checkpoint(out_dir, model.solid, model.engine, model.interface)
    else:
        save_engine_checkpoint(model.engine, staged(out_dir / "checkpoint.npz"))
        finals = [out_dir / "checkpoint.npz"] if is_root() else []
    if is_root():
        atomic_write_text(staged(out_dir / state_file),
                          json.dumps({**state, "step": model.engine.step_count}, indent=1))
        finals.append(out_dir / state_file)
    commit_checkpoint(out_dir, finals)


def checkpointed_engine(case_path, out_dir, state, state_file):
    """The DEM engine of the last checkpoint (any rank count), checked against the loop's
    ``state``; collective."""
    from cosim.apps import dem as dem_app
    comm = mpi_comm()
    engine = dem_app.load_checkpoint(case_path, out_dir / "checkpoint.npz", comm if comm.size > 1 else None)
    if engine.step_count != state["step"]:
        raise CaseError(out_dir / state_file, "step", state["step"],
                        f"does not match the checkpoint (step {engine.step_count}); run without --resume")
    return engine


def restore_fe(solid, interface, engine, case_path, out_dir):
    """The FE state of the last checkpoint into ``solid`` (built afresh on the prepared mesh),
    the interface tied to the engine's last facet mesh, and the interface force in transit
    made again from the saved impulse; collective."""
    from cosim.apps import coupled as coupled_app
    from cosim.apps import fe as fe_app
    fe_state = fe_app.restore_checkpoint(solid, case_path, out_dir, coupled_app.FE_CHECKPOINT_STEM)
    if abs(engine.time - solid.time) > 0.5 * engine.dt:  # files of two runs mixed by hand
        raise CaseError(case_path, "--resume", str(out_dir / "checkpoint.npz"),
                        "the DEM and FE checkpoints are of different instants; run without --resume")
    if "interface_held" in fe_state:
        interface.held[:] = fe_state["interface_held"]
    interface.facets = engine.facets[-1]  # the interface is the last facet mesh
    interface.receive_forces(solid.dt)


def fe_nodes(solid):
    """(coordinates, displacement) of every FE node, in mesh-input order, on rank 0 (None on
    the others); collective over the FE's ranks."""
    owned = slice(0, solid.n_owned_nodes)
    rows = np.hstack([solid.input_node_index[owned, None].astype(np.float64), solid.node_coordinates[owned],
                      solid.displacement[owned]])
    parts = solid.comm.gather(rows, root=0)
    if not is_root():
        return None, None
    rows = np.concatenate(parts)
    rows = rows[np.argsort(rows[:, 0], kind="stable")]
    return rows[:, 1:4], rows[:, 4:7]
