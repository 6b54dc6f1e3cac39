"""An FE–DE coupled run set up in Python, without a case file.

Thirty grains fly up, with no gravity, into the underside of a free elastic plate. The
plate is an explicit mixed u–p finite-element solid (``fe_domain``); its tagged face
``bottom`` is the coupling interface, which the DEM (``de_domain``) sees as a triangle
facet mesh whose vertices are the FE nodes (docs/design.md §5). Per FE step:

1. the FE advances with the interface force of the last window;
2. the interface vertices start at X + uⁿ and move with v^{n+½};
3. the DEM runs ``subcycles`` steps against them and accumulates the impulse per node;
4. impulse / Δt_FE is the interface force of the next FE step.

Nothing else acts on either body, so the linear momentum of FE + DEM + the impulse in
transit (collected by the DEM, not yet applied to the FE) is conserved to round-off:
the script checks that, and that the plate really picked up the grains' momentum.

Run (serial, or with the FE and the DEM both spread over the ranks)::

    .venv/bin/python examples/coupled_without_toml.py [OUT_DIR]
    mpirun -n 2 .venv/bin/python examples/coupled_without_toml.py [OUT_DIR]

``OUT_DIR`` (default: a new temporary folder) receives ``series.csv``, ``fields.xdmf``
(FE u, v, p, von Mises) and ``particles.pvd`` with its VTU frames (grains + interface).
The last line printed is ``momentum conserved to X relative`` (the script fails with
an AssertionError if X > 1e-12).
"""
import sys
import tempfile
from pathlib import Path

import numpy as np
from mpi4py import MPI

from cosim.apps.coupled import coupled_step, momentum, time_steps
from cosim.compiled_coupling import CoupledStepper
from cosim.interface import Interface
from cosim.outputs import CsvSeries, PvdCollection
from de_domain import Engine, Material, Particles
from de_domain.io import write_frame
from de_domain.packing import random_cloud
from fe_domain.build import build_solid
from fe_domain.explicit import stable_alpha_tau
from fe_domain.output import FieldWriter

comm = MPI.COMM_WORLD
root = comm.rank == 0
out = Path(sys.argv[1]) if len(sys.argv) > 1 else (Path(tempfile.mkdtemp(prefix="coupled_")) if root else None)
out = comm.bcast(out, root=0)  # every rank writes its part of the XDMF into the same folder
if root:
    out.mkdir(parents=True, exist_ok=True)
comm.Barrier()

# 1. The FE plate: meshes/block.geo (physical faces x0 x1 y0 y1 bottom top) as a 10 x 10 x 4 mm
#    block, meshed by gmsh on rank 0 and distributed; E = 10 MPa, no supports, no loads.
nu = 0.3
solid = build_solid("block.geo", 0.004, material={"E": 1.0e7, "nu": nu, "rho": 2000.0},
                    geometry_parameters={"Lx": 0.01, "Ly": 0.01, "Lz": 0.004},
                    formulation="mixed", alpha_tau=stable_alpha_tau(nu))

# 2. The interface (collective): the plate's underside as a DEM facet mesh of material 0.
interface = Interface(solid, ["bottom"], material=0)

# 3. The grains (the same on every rank; with several ranks the engine keeps each rank's
#    share): a cloud below the plate, all moving up at 0.5 m/s.
grain = Material(density=2650.0, young=1.0e7, friction=0.5, restitution=0.5)
rng = np.random.default_rng(3)
positions, radii = random_cloud(rng.uniform(0.5e-3, 0.6e-3, 30), (0.001, 0.001, -0.004),
                                (0.009, 0.009, -0.0002), seed=3)
particles = Particles.from_spheres(positions, radii, materials=[grain],
                                   velocities=np.tile([0.0, 0.0, 0.5], (len(radii), 1)))
engine = Engine(particles, [grain], facets=[interface.facets], gravity=(0.0, 0.0, 0.0), safety_factor=0.3,
                comm=comm if comm.size > 1 else None)

# 4. Time steps: DT_FE = n DT_DE, both within their stability limits (0.3 of the critical ones).
fe_dt, dem_dt, subcycles = time_steps(engine.dt, 0.3 * solid.dt_critical)
solid.dt = fe_dt
engine.dt = dem_dt
if root:
    print(f"FE dt = {fe_dt:.3e} s, DEM dt = {dem_dt:.3e} s ({subcycles} DEM steps per FE step), "
          f"{comm.size} rank(s)")

# 5. The loop: one coupled step at a time; every 100 FE steps a CSV row, FE fields and a frame.
columns = ["time", "momentum_fe_z", "momentum_dem_z", "impulse_in_transit_z", "momentum_total_z"]
series = CsvSeries(out / "series.csv", columns) if root else None
frames = PvdCollection(out / "particles.pvd") if root else None
fields = FieldWriter(solid, out / "fields", extra_fields=[interface.traction_field])   # collective
totals = []


def record():
    fe, dem, transit = momentum(solid, engine, interface)   # collective
    fields.write()
    paths = write_frame(out / "frames", engine, solid.step_count)   # collective; rank 0 writes
    if root:
        total = fe + dem + transit
        totals.append(total)
        series.append([solid.time, fe[2], dem[2], transit[2], total[2]])
        frames.add(engine.time, paths)
        print(f"  t = {solid.time:.3e} s: momentum FE {fe[2]:.4e}, DEM {dem[2]:.4e}, in transit {transit[2]:+.1e}, "
              f"total {total[2]:.6e} N s")


record()
p0 = totals[0][2] if root else None
# coupled_step makes one FE step and its DEM window from Python; the stepper makes them in
# compiled calls on one rank (bit-identically), and calls coupled_step on several
stepper = CoupledStepper(solid, engine, interface, subcycles)
steps = int(np.ceil(0.006 / solid.dt))
while solid.step_count < steps:
    stepper.run(min(100 - solid.step_count % 100, steps - solid.step_count), coupled_step)
    record()
fields.close()
fe_end = momentum(solid, engine, interface)[0]   # collective

# 6. Checks (rank 0): the momentum books close, and the plate took a good part of it.
if root:
    series.close()
    drift = float(np.max(np.abs(np.array(totals) - totals[0])) / p0)
    fe_share = fe_end[2] / p0
    print(f"outputs in {out}")
    print(f"the plate carries {100 * fe_share:.0f} % of the grains' initial momentum")
    print(f"momentum conserved to {drift:.1e} relative")
    assert fe_share > 0.3 and drift < 1e-12
