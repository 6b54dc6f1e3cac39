"""The ``dem`` case kind under ``mpirun -n 2`` runs the DEM distributed over both ranks:
its outputs match a serial run (final packing bit for bit, the CSV series to rounding),
are written once, and a run stopped part-way resumes under MPI from its distributed
checkpoint to the same end state.

Each command runs under a timeout far above its normal time: a hang fails the test."""
import csv
import os
import subprocess
import sys
import tomllib
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import tomli_w

from de_domain.io import read_frame

ROOT = Path(__file__).parents[2]
COSIM = Path(sys.executable).parent / "cosim"
DEMO = ROOT / "runs" / "demo_dem_settling.toml"
ENV = {**os.environ, "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1",
       "OMPI_MCA_rmaps_base_oversubscribe": "1", "NUMBA_NUM_THREADS": "1"}
TIMEOUT = 240  # s; each run below takes a few seconds
STEPS = 400


def shrunk_case(tmp_path, demo, name, count, side, top):
    """``demo`` with ``count`` grains in a ``side``-wide box up to ``top``, 400 steps, frames."""
    data = tomllib.loads(demo.read_text())
    data["case"]["name"] = name
    data["dem"]["particles"]["count"] = count
    data["dem"]["particles"]["box"] = [[0.0, 0.0, 0.0], [side, side, top]]
    for w in data["dem"]["walls"]:
        w["point"] = [min(c, side) for c in w["point"]]
    data["time"] = {"steps": STEPS, "safety_factor": 0.3}
    data["output"] = {"interval": 1e-4, "vtk": True}
    path = tmp_path / f"{name}.toml"
    path.write_text(tomli_w.dumps(data))
    return path


def small_case(tmp_path, count=300):
    """The small settling case of test_dem_case_run.py: 300 spheres, 400 steps, frames."""
    return shrunk_case(tmp_path, DEMO, "small_mpi", count, 0.015, 0.03)


def cosim(*args, n=None):
    command = [str(COSIM), *args] if n is None else ["mpirun", "-n", str(n), "--oversubscribe", "--bind-to", "none",
                                                    str(COSIM), *args]
    done = subprocess.run(command, capture_output=True, text=True, env=ENV, cwd=ROOT, timeout=TIMEOUT)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    return done


def rows(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def assert_series_agree(a, b):
    """The same rows (time, step exact); the diagnostics to 1e-9 relative, the energy
    books to 1e-9 of the largest energy in the row (the residual is a difference of totals:
    rank-order sums change its last bits)."""
    assert [(r["time"], r["step"]) for r in a] == [(r["time"], r["step"]) for r in b]
    diagnostics = ["unbalanced_force_ratio", "coordination_number"]
    energies = [k for k in a[0] if k not in ("time", "step", *diagnostics)]
    for ra, rb in zip(a, b, strict=True):
        for k in diagnostics:
            assert abs(float(ra[k]) - float(rb[k])) <= 1e-9 * abs(float(ra[k])) + 1e-12, (k, ra[k], rb[k])
        scale = max(max(abs(float(r[k])) for k in energies) for r in (ra, rb))
        for k in energies:
            assert abs(float(ra[k]) - float(rb[k])) <= 1e-9 * scale, (k, ra[k], rb[k])


def packing(path):
    with np.load(path) as f:
        return {k: f[k] for k in f.files}


def datasets(out):
    return [d.get("file") for d in ET.parse(out / "particles.pvd").getroot().iter("DataSet")]


def last_frame(out):
    """The last particle frame of ``out``'s ParaView collection (a serial run's ``.vtu``, a
    distributed run's ``.pvtu`` and its pieces), read back in global-id order."""
    files = [out / f for f in datasets(out)]
    assert all(f.exists() for f in files)
    return read_frame(files[-1])


def assert_same_frame(a, b):
    (points, fields), (other_points, other_fields) = a, b
    np.testing.assert_array_equal(points, other_points)
    assert fields.keys() == other_fields.keys()
    for name in fields:
        np.testing.assert_array_equal(fields[name], other_fields[name])


def test_dem_case_under_mpirun_matches_the_serial_run_and_resumes(tmp_path):
    case = small_case(tmp_path)
    serial, mpi, split = tmp_path / "serial", tmp_path / "mpi", tmp_path / "split"
    cosim("run", str(case), "--out", str(serial))
    res = cosim("run", str(case), "--out", str(mpi), n=2)
    assert res.stdout.count("outputs: ") == 1 and "on 2 MPI ranks" in res.stdout  # rank 0 speaks, once

    a, b = packing(serial / "final_packing.npz"), packing(mpi / "final_packing.npz")
    assert a.keys() == b.keys()
    for k in a:
        np.testing.assert_array_equal(a[k], b[k])  # bit for bit
    assert a["positions"].shape == (300, 3)
    assert_series_agree(rows(serial / "series.csv"), rows(mpi / "series.csv"))
    frame = last_frame(mpi)  # the pieces of both ranks: each particle once
    assert frame[0].shape == (300, 3) and str(datasets(mpi)[-1]).endswith(".pvtu")
    assert_same_frame(frame, last_frame(serial))
    assert not list(mpi.glob("*.tmp.npz"))

    # stopped part-way under MPI (between two output rows: that final row is dropped on resume),
    # resumed under MPI from the distributed checkpoint
    stop = STEPS // 2 + 20
    assert str(stop) not in [r["step"] for r in rows(serial / "series.csv")]
    cosim("run", str(case), "--out", str(split), "--set", f"time.steps={stop}", n=2)
    assert float(rows(split / "series.csv")[-1]["step"]) == stop
    cosim("run", str(case), "--out", str(split), "--resume", n=2)
    c = packing(split / "final_packing.npz")
    for k in a:
        np.testing.assert_array_equal(a[k], c[k])
    assert_series_agree(rows(serial / "series.csv"), rows(split / "series.csv"))
    assert_same_frame(last_frame(split), last_frame(serial))


def small_clump_case(tmp_path):
    """The clumps demo (rods and bent three-sphere grains) made small: 120 grains in a 20 mm box,
    400 steps, frames."""
    return shrunk_case(tmp_path, ROOT / "runs" / "demo_dem_clumps.toml", "small_clumps_mpi", 120, 0.02, 0.06)


def test_clumped_dem_case_under_mpirun_matches_the_serial_run_and_resumes(tmp_path):
    """Clumps under ``mpirun -n 2`` (a clump straddling the ranks advanced on both from the
    members' loads of both): the members and the clumps' state bit for bit, the frames with each member's
    clump, and a run stopped part-way resumes on 2 ranks to the same end."""
    case = small_clump_case(tmp_path)
    serial, mpi, split = tmp_path / "serial", tmp_path / "mpi", tmp_path / "split"
    cosim("run", str(case), "--out", str(serial))
    cosim("run", str(case), "--out", str(mpi), n=2)
    stop = STEPS // 2 + 20
    cosim("run", str(case), "--out", str(split), "--set", f"time.steps={stop}", n=2)
    cosim("run", str(case), "--out", str(split), "--resume", n=2)
    for out in (mpi, split):
        for name in ("final_packing.npz", "final_clumps.npz"):
            a, b = packing(serial / name), packing(out / name)
            assert a.keys() == b.keys()
            for k in a:
                np.testing.assert_array_equal(a[k], b[k])  # bit for bit
        assert_series_agree(rows(serial / "series.csv"), rows(out / "series.csv"))
        assert_same_frame(last_frame(out), last_frame(serial))
    assert packing(serial / "final_clumps.npz")["mass"].size == 120
    assert "clump" in last_frame(mpi)[1]


DIAGNOSTICS_SCRIPT = """
import numpy as np
from mpi4py import MPI
from de_domain import Engine, Material, Particles, PlaneWall
from de_domain import diagnostics as dg

comm = MPI.COMM_WORLD
mat = [Material(young=5e7, friction=0.5, restitution=0.5)]
rng = np.random.default_rng(3)  # a squeezed lattice: many contacts from the first step
grid = np.stack(np.meshgrid(*[np.arange(6)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
pos = 1e-3 + 1.97e-3 * grid + rng.uniform(-1e-5, 1e-5, grid.shape)
radii = rng.uniform(0.99e-3, 1.01e-3, len(pos))

def build(c):
    p = Particles.from_spheres(pos, radii, materials=mat)
    walls = [PlaneWall((0, 0, 0), (0, 0, 1)), PlaneWall((0, 0, 0), (1, 0, 0)), PlaneWall((0.012, 0, 0), (-1, 0, 0))]
    return Engine(p, mat, walls=walls, comm=c)

serial, spread = build(None), build(comm)
for e in (serial, spread):
    e.run(60)
box, ball = dg.BoxRegion((0.0, 0.0, 0.0), (0.012, 0.012, 0.005)), dg.SphereRegion((0.006, 0.006, 0.004), 0.004)
checks = {"kinetic": lambda e: dg.kinetic_energy(e), "ufr": lambda e: dg.unbalanced_force_ratio(e),
          "z": lambda e: dg.coordination_number(e), "z_box_walls": lambda e: dg.coordination_number(e, box, True),
          "solid_box": lambda e: dg.solid_volume(e, box), "solid_ball": lambda e: dg.solid_volume(e, ball),
          "stress": lambda e: dg.love_weber_stress(e, box)}
assert len(serial.contacts()["i"]) > 100, len(serial.contacts()["i"])
for name, f in checks.items():
    a, b = np.asarray(f(serial)), np.asarray(f(spread))
    assert np.allclose(a, b, rtol=1e-12, atol=1e-12 * np.abs(a).max()), (name, a, b)
    every = comm.allgather(b.tobytes())
    assert all(x == every[0] for x in every), name  # the same bits on every rank
assert spread.particles.ghost.any() or comm.size == 1
print("diagnostics agree", comm.rank, flush=True)
"""


def test_diagnostics_of_a_distributed_engine_are_global_and_the_same_on_every_rank():
    """Each diagnostic of a distributed engine equals the serial one (to rounding: the
    ranks' partial sums are added in rank order) and has the same bits on every rank."""
    done = subprocess.run(["mpirun", "-n", "2", "--oversubscribe", "--bind-to", "none", sys.executable, "-c",
                           DIAGNOSTICS_SCRIPT], capture_output=True, text=True, env=ENV, cwd=ROOT, timeout=TIMEOUT)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    assert done.stdout.count("diagnostics agree") == 2
