"""Case kind ``triaxial``: a drained triaxial compression test on a cubical specimen
(docs/design.md §3.10).

The run, top to bottom:

1. **Specimen**: the ``[specimen]`` generation (``cosim.specimen``) in an L × L box, to the
   height L, or a packing file. It is saved as ``specimen.npz``.
2. **Cell**: six frictionless rigid plane walls (a lubricated cell; ``cosim.lab.cubical_box``).
   The walls at x = 0, y = 0 and the bottom stay; the walls at x = L_x, y = L_y and the top
   move. The grains have their real density.
3. **Isotropic consolidation**: the three moving walls are servo-controlled to σ₃
   (``cell_pressure``) until every wall stress is within ``consolidation_tolerance`` of it
   and the unbalanced force ratio is low.
4. **Axial compression**: the top wall moves down at v = ε̇ H₀ (a constant nominal strain
   rate; ε̇ from the inertial number I = ε̇ d₅₀ √(ρ/σ₃) = 10⁻³ unless ``strain_rate`` is
   given), ramped up from 2 % over ``ramp_strain``. The two lateral walls hold σ₃, until
   ε₁ = ``axial_strain``. A CSV row is written
   every ``axial_strain / rows``, with the wall stresses averaged over the servo updates
   since the last row.

Each servo wall uses the direct shear's law (``cosim.lab.shear_box.servo_velocity``): per
update it removes ``servo_gain`` of the stress error, scaled by its contacts' stiffness,
plus a small integral term (``servo_integral``), so that σ₃ does not lag a steadily
dilating specimen.

Measured (``series.csv``; compression and contraction positive):

  * ε₁ = (H₀ − H)/H₀ and ε_v = (V₀ − V)/V₀, with V = L_x L_y H and the values at the end of
    consolidation;
  * σ₁ = F_top/(L_x L_y), σ_x = F_x/(L_y H), σ_y = F_y/(L_x H), σ₃ = (σ_x + σ_y)/2;
  * q = σ₁ − σ₃, p = (σ₁ + 2σ₃)/3 and the mobilised sin φ = (σ₁ − σ₃)/(σ₁ + σ₃);
  * the void ratio e = V/V_s − 1, the unbalanced force ratio and the coordination number.

Report (``summary.json``/``.txt``): φ_peak = asin(max sin φ), and the critical-state φ from the
mean σ₁ and σ₃ over the last ``residual_fraction`` of ε₁ (the summary's
``residual_friction_angle_deg``, the name the direct shear uses, so that ``cosim series``
and ``cosim calibrate`` read both kinds alike). Also ε_v at the peak and at the end, the void
ratios and the servo error. ``triaxial.png`` plots q and ε_v against ε₁.
"""
from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np

from cosim.errors import CaseError
from cosim.outputs import (
    CsvSeries,
    ProgressLine,
    atomic_write_text,
    is_root,
    load_lab_checkpoint,
    mpi_comm,
    particle_frames,
    save_lab_checkpoint,
    say,
    write_run_metadata,
)
from cosim.specimen import SpecimenBox, check_grain_time_step, lab_specimen, read_lab_inputs

CHECKPOINT = "checkpoint.npz"
STATE = "triaxial_state.json"
MOVING = (1, 3, 5)  # wall indices: x = L_x, y = L_y, top
STIFFNESS_REFRESH = 25  # steps between updates of a servo wall's contact stiffness
COLUMNS = ["time", "axial_strain", "volumetric_strain", "sigma_1", "sigma_x", "sigma_y", "sigma_3",
           "deviator_stress", "mean_stress", "sin_phi_mobilised", "void_ratio", "unbalanced_force_ratio",
           "coordination_number", "step"]


# --------------------------------------------------------------------------- inputs
def materials(case):
    """de_domain Materials from [dem.materials] and the ids of the grains, the walls and
    the generation plate."""
    from cosim.apps.dem import materials_of
    tx = case.triaxial
    return materials_of(case.dem, tx.sand_material, tx.wall_material, tx.plate_material)


def prepare(case, case_path, out_dir, resume):
    """Every input check before computing, on rank 0: the checkpoint to resume from, the
    packing file or the sieve curve, a given dt against the smallest grain's critical step."""
    if not is_root():
        return None
    tx = case.triaxial
    out_dir = Path(out_dir)
    if resume and not ((out_dir / CHECKPOINT).exists() and (out_dir / STATE).exists()):
        raise CaseError(case_path, "--resume", str(out_dir / CHECKPOINT),
                        "no triaxial checkpoint in the output folder (checkpoints start with the compression); "
                        "run without --resume")
    built, r_min = read_lab_inputs(case, case_path, tx.size, tx.size)
    mats, sand, _, _ = materials(case)
    check_grain_time_step(case, case_path, mats, sand, r_min)
    return built


def make_specimen(case, built, out_dir, cache=None, comm=None):
    """The specimen in the L × L cell, generated to the height L or read from its file;
    returns (positions, radii, height, info); collective with ``comm``."""
    tx = case.triaxial
    return lab_specimen(case, built, SpecimenBox(tx.size, tx.size, tx.size, *materials(case)), out_dir, cache, comm)


# --------------------------------------------------------------------------- the cell
class TriaxialTest:
    """Engine + six walls + the servo of the three moving walls (module docstring, steps 2–4)."""

    SERVO_STATE = ("stiffness", "stiffness_step", "v_integral")

    def __init__(self, case, engine):
        from cosim.lab.shear_box import mass_median_diameter
        self.case, self.tx = case, case.triaxial
        mats, sand, wall, _ = materials(case)
        self.young_grain, self.young_wall = mats[sand].young, mats[wall].young
        self.density = mats[sand].density
        self.engine = engine
        self.radii = engine.global_particles().radius  # collective when distributed
        self.solid_volume = float(np.sum(4.0 / 3.0 * np.pi * self.radii ** 3))
        self.d50 = mass_median_diameter(self.radii)
        self.rate = strain_rate_of(self.tx, self.d50, self.density)
        self.max_velocity = self.tx.servo_max_velocity or 2.0 * self.rate * self.tx.size
        self.stiffness = [0.0, 0.0, 0.0]
        self.stiffness_step = None
        self.v_integral = [0.0, 0.0, 0.0]

    @classmethod
    def build(cls, case, positions, radii, height, comm=None):
        from cosim.lab.cubical_box import box_walls
        from de_domain import Engine, Particles
        mats, sand, wall, _ = materials(case)
        L = case.triaxial.size
        particles = Particles.from_spheres(positions, radii, np.full(len(radii), sand, np.int32), mats)
        dem = case.dem
        engine = Engine(particles, mats, walls=box_walls(L, L, height, wall), contact_law=dem.contact_law,
                        gravity=dem.gravity, dt=case.time.dt, safety_factor=case.time.safety_factor,
                        local_damping=dem.local_damping, viscous_damping=dem.viscous_damping, comm=comm)
        return cls(case, engine)

    # ---------------------------------------------------------------- measurements
    def stresses(self):
        """(σ_x, σ_y, σ_z) on the moving walls, compression +."""
        from cosim.lab.cubical_box import wall_stresses
        return wall_stresses(self.engine)

    def lengths(self):
        from cosim.lab.cubical_box import box_lengths
        return box_lengths(self.engine)

    def volume(self):
        return float(np.prod(self.lengths()))

    def void_ratio(self):
        return self.volume() / self.solid_volume - 1.0

    # ---------------------------------------------------------------- servo step
    def step(self, axial_velocity=None):
        """``servo_interval`` DEM steps. The lateral walls (and, while consolidating, the top)
        move by the servo law toward σ₃; with ``axial_velocity`` the top moves down at it."""
        from cosim.apps.dem import advance
        from cosim.lab.shear_box import plate_contact_stiffness, servo_velocity
        tx, engine = self.tx, self.engine
        if self.stiffness_step is None or engine.step_count - self.stiffness_step >= STIFFNESS_REFRESH:
            self.stiffness = [plate_contact_stiffness(engine.wall_contact_particles(w), self.radii,
                                                      self.young_grain, self.young_wall) for w in MOVING]
            self.stiffness_step = engine.step_count
        sigma, lengths = self.stresses(), self.lengths()
        areas = (lengths[1] * lengths[2], lengths[0] * lengths[2], lengths[0] * lengths[1])
        servo_axes = (0, 1) if axial_velocity is not None else (0, 1, 2)
        for axis in range(3):
            wall = engine.walls[MOVING[axis]]
            if axis not in servo_axes:
                wall.velocity = np.array([0.0, 0.0, -axial_velocity])
                continue
            v_max = self.max_velocity
            v = servo_velocity(sigma[axis], tx.cell_pressure, areas[axis], self.stiffness[axis],
                               engine.dt * tx.servo_interval, tx.servo_gain, v_max)
            if self.stiffness[axis] > 0.0:  # integral action: no steady lag while the specimen dilates
                self.v_integral[axis] = float(np.clip(self.v_integral[axis] + tx.servo_integral * v, -v_max, v_max))
            v = float(np.clip(v + self.v_integral[axis], -v_max, v_max))
            wall.velocity = np.eye(3)[axis] * v
        advance(engine, tx.servo_interval)

    def consolidate(self, log):
        """Step 3: the three moving walls to σ₃; returns the steps taken."""
        from de_domain.diagnostics import unbalanced_force_ratio
        tx = self.tx
        per_check = max(1, 100 // tx.servo_interval)
        window, n = [], 0
        while n < tx.max_consolidation_steps:
            self.step()
            n += tx.servo_interval
            window.append(self.stresses())
            if len(window) % per_check == 0:
                mean = np.mean(window[-per_check:], axis=0)
                if np.all(np.abs(mean - tx.cell_pressure) < tx.consolidation_tolerance * tx.cell_pressure):
                    uf = unbalanced_force_ratio(self.engine)
                    if uf < tx.consolidation_unbalanced_force:
                        log(f"consolidated to sigma = {np.array2string(mean, precision=4)} Pa in {n} steps "
                            f"(unbalanced force {uf:.3g}), e = {self.void_ratio():.4f}")
                        return n
        log(f"consolidation stopped after {tx.max_consolidation_steps} steps: sigma = "
            f"{np.array2string(self.stresses(), precision=4)} Pa")
        return n


# --------------------------------------------------------------------------- the run
def run(prepared, specimen_cache=None):
    """The test; under ``mpirun -n N`` the DEM is spread over all ranks."""
    case = prepared.case
    write_run_metadata(prepared.out_dir, prepared.case_path, prepared.resolved, case.case.seed)
    comm = mpi_comm()
    if comm.size > 1 or is_root():
        _run_test(case, prepared.out_dir, prepared.built, specimen_cache, prepared.resume,
                  comm if comm.size > 1 else None)
    comm.Barrier()


def _save_checkpoint(out_dir, test, loop):
    state = {**{k: getattr(test, k) for k in TriaxialTest.SERVO_STATE}, **loop}
    save_lab_checkpoint(out_dir, test.engine, STATE, state)  # collective when distributed


def _load_checkpoint(case, out_dir, comm=None):
    engine, state = load_lab_checkpoint(out_dir, STATE, comm)
    test = TriaxialTest(case, engine)
    for k in TriaxialTest.SERVO_STATE:
        setattr(test, k, state[k])
    return test, state


def _record(test, sums, n, loop):
    """One CSV row: the wall stresses averaged over the ``n`` updates in ``sums``."""
    from de_domain.diagnostics import coordination_number, unbalanced_force_ratio
    sx, sy, s1 = sums / n
    s3 = 0.5 * (sx + sy)
    lengths = test.lengths()
    e1 = (loop["height0"] - lengths[2]) / loop["height0"]
    ev = (loop["volume0"] - float(np.prod(lengths))) / loop["volume0"]
    return [test.engine.time, e1, ev, s1, sx, sy, s3, s1 - s3, (s1 + 2.0 * s3) / 3.0, (s1 - s3) / (s1 + s3),
            test.void_ratio(), unbalanced_force_ratio(test.engine), coordination_number(test.engine),
            test.engine.step_count]


def strain_rate_of(tx, d50, density):
    """ε̇: ``strain_rate``, or from the inertial number I = ε̇ d₅₀ √(ρ/σ₃)."""
    return tx.strain_rate or tx.inertial_number / (d50 * math.sqrt(density / tx.cell_pressure))


def _run_test(case, out_dir, built, specimen_cache, resume=False, comm=None):
    name, tx = case.case.name, case.triaxial
    log = lambda text: say(f"[{name}] {text}")  # noqa: E731
    t_start = time.perf_counter()
    if resume:
        test, loop = _load_checkpoint(case, out_dir, comm)
        engine = test.engine
        log(f"resumed at step {engine.step_count}")
    else:
        if comm is not None:
            built = comm.bcast(built, root=0)
        positions, radii, height, specimen_info = make_specimen(case, built, out_dir, specimen_cache, comm)
        test = TriaxialTest.build(case, positions, radii, height, comm)
        engine = test.engine
        log(f"cell {tx.size * 1e3:.1f} x {tx.size * 1e3:.1f} x {height * 1e3:.2f} mm, {test.radii.size} grains "
            f"(d50 = {test.d50 * 1e3:.2f} mm), dt = {engine.dt:.3e} s"
            + (f", DEM on {comm.size} MPI ranks" if comm is not None else ""))
        t_consolidation = time.perf_counter()
        consolidation_steps = test.consolidate(log)
        lengths = test.lengths()
        loop = {"specimen_info": specimen_info, "consolidation_steps": consolidation_steps,
                "e_consolidated": test.void_ratio(), "height0": float(lengths[2]), "volume0": float(np.prod(lengths)),
                "next_row": 0.0, "sums": [0.0, 0.0, 0.0], "n": 0, "next_frame": 0.0,
                "wall_clock_consolidation_s": time.perf_counter() - t_consolidation, "wall_clock_compression_s": 0.0,
                "wall_clock_before_s": 0.0}

    rate = test.rate
    velocity = rate * loop["height0"]
    # the ramp from 2 % of the rate over ramp_strain takes ln(50) ramp_strain / rate
    total_steps = loop["consolidation_steps"] + int(math.ceil(
        (tx.axial_strain + (math.log(50.0) - 1.0) * tx.ramp_strain) / (rate * engine.dt)))
    log(f"compressing at eps_dot = {rate:.4g} 1/s (top wall {velocity:.4g} m/s, inertial number "
        f"{rate * test.d50 * math.sqrt(test.density / tx.cell_pressure):.2e}) to eps_1 = {tx.axial_strain}: "
        f"about {total_steps - loop['consolidation_steps']} steps")
    series = CsvSeries(out_dir / "series.csv", COLUMNS, resume_time=engine.time if resume else None) \
        if is_root() else None
    frames = particle_frames(case.output.vtk, out_dir, loop, tx.axial_strain / 10, engine.time if resume else None)
    if not resume:
        frames(engine, 0.0)
    progress = ProgressLine(name, total_steps, case.output.progress_interval, first_step=engine.step_count)
    spacing = tx.axial_strain / tx.rows
    sums, n = np.array(loop["sums"]), loop["n"]
    t0 = last_checkpoint = time.perf_counter()
    strain = (loop["height0"] - test.lengths()[2]) / loop["height0"]
    while True:
        ramp = min(1.0, max(0.02, strain / tx.ramp_strain)) if tx.ramp_strain > 0 else 1.0
        test.step(axial_velocity=velocity * ramp)
        sums += test.stresses()
        n += 1
        strain = (loop["height0"] - test.lengths()[2]) / loop["height0"]
        done = strain >= tx.axial_strain
        if strain >= loop["next_row"] or done:
            row = _record(test, sums, n, loop)  # collective when distributed
            if series is not None:
                series.append(row)
            sums, n = np.zeros(3), 0
            loop["next_row"] += spacing
            frames(engine, strain)
        progress.update(engine.step_count, engine.time)
        if done:
            break
        due = time.perf_counter() - last_checkpoint > case.output.checkpoint_interval
        if due if comm is None else comm.bcast(due, root=0):
            now = time.perf_counter()
            loop.update(sums=sums.tolist(), n=n,
                        wall_clock_compression_s=loop["wall_clock_compression_s"] + now - t0,
                        wall_clock_before_s=loop["wall_clock_before_s"] + now - t_start)
            t0 = t_start = last_checkpoint = now
            _save_checkpoint(out_dir, test, loop)
    progress.update(engine.step_count, engine.time, force=True)
    if not is_root():
        return None
    series.close()
    from cosim.lab.shear_report import read_series
    data = read_series(out_dir / "series.csv")
    summary = summarize(data, tx.residual_fraction)
    summary.update({
        "case": name, "grains": int(test.radii.size), "d50": test.d50, "size": tx.size,
        "cell_pressure": tx.cell_pressure, "strain_rate": rate,
        "inertial_number": rate * test.d50 * math.sqrt(test.density / tx.cell_pressure), "dt": engine.dt,
        "steps_consolidation": loop["consolidation_steps"],
        "steps_compression": int(engine.step_count - loop["consolidation_steps"]),
        "void_ratio_consolidated": loop["e_consolidated"], "void_ratio_end": float(data["void_ratio"][-1]),
        **servo_errors(data, tx.cell_pressure),
        "wall_clock_consolidation_s": loop["wall_clock_consolidation_s"],
        "wall_clock_compression_s": loop["wall_clock_compression_s"] + time.perf_counter() - t0,
        "wall_clock_total_s": loop["wall_clock_before_s"] + time.perf_counter() - t_start,
        **{k: v for k, v in loop["specimen_info"].items() if k != "generation_log"},
    })
    atomic_write_text(out_dir / "summary.json", json.dumps(summary, indent=2))
    atomic_write_text(out_dir / "summary.txt", summary_text(summary))
    plot_run(data, out_dir / "triaxial.png", f"{name}: σ₃ = {tx.cell_pressure / 1e3:g} kPa")
    for line in summary_text(summary).splitlines():
        log(line)
    return summary


# --------------------------------------------------------------------------- report
def summarize(data, residual_fraction=0.2):
    """Peak and critical-state friction angles and the volume change of one test
    (module docstring)."""
    e1, s1, s3, ev = data["axial_strain"], data["sigma_1"], data["sigma_3"], data["volumetric_strain"]
    ratio = (s1 - s3) / (s1 + s3)
    peak = int(np.argmax(ratio))
    late = e1 >= (1.0 - residual_fraction) * e1[-1]
    s1_cs, s3_cs = float(np.mean(s1[late])), float(np.mean(s3[late]))
    return {
        "peak_sin_phi": float(ratio[peak]), "peak_friction_angle_deg": math.degrees(math.asin(ratio[peak])),
        "peak_axial_strain": float(e1[peak]), "peak_deviator_stress": float(s1[peak] - s3[peak]),
        "residual_sin_phi": (s1_cs - s3_cs) / (s1_cs + s3_cs),
        "residual_friction_angle_deg": math.degrees(math.asin((s1_cs - s3_cs) / (s1_cs + s3_cs))),
        "residual_sigma_1": s1_cs, "residual_sigma_3": s3_cs,
        "peak_shear_stress": float(0.5 * (s1[peak] - s3[peak])),
        "peak_normal_stress": float(0.5 * (s1[peak] + s3[peak])),
        "residual_shear_stress": 0.5 * (s1_cs - s3_cs), "residual_normal_stress": 0.5 * (s1_cs + s3_cs),
        "volumetric_strain_at_peak": float(ev[peak]), "volumetric_strain_end": float(ev[-1]),
        "volume_change": "dilation" if ev[-1] < 0 else "contraction",
    }


def servo_errors(data, target):
    """``|σ₃ − target|/target`` over the CSV rows (σ₃ the mean of the two lateral walls), and the
    largest error of one wall alone."""
    sigma_3 = np.abs(data["sigma_3"] / target - 1.0)
    walls = np.maximum(np.abs(data["sigma_x"] / target - 1.0), np.abs(data["sigma_y"] / target - 1.0))
    return {"servo_max_relative_error": float(sigma_3.max()), "servo_mean_relative_error": float(sigma_3.mean()),
            "servo_max_wall_relative_error": float(walls.max())}


def summary_text(s):
    return "\n".join([
        f"grains {s['grains']}, d50 {s['d50'] * 1e3:.2f} mm, cell {s['size'] * 1e3:.1f} mm, "
        f"sigma_3 {s['cell_pressure'] / 1e3:g} kPa",
        f"void ratio: consolidated {s['void_ratio_consolidated']:.4f}, end {s['void_ratio_end']:.4f}",
        f"peak sin phi {s['peak_sin_phi']:.3f} (phi_peak {s['peak_friction_angle_deg']:.1f} deg) at eps_1 "
        f"{100 * s['peak_axial_strain']:.1f} %, q {s['peak_deviator_stress'] / 1e3:.1f} kPa; critical state "
        f"(last part of eps_1) phi {s['residual_friction_angle_deg']:.1f} deg",
        f"volumetric strain (contraction +) at the peak {100 * s['volumetric_strain_at_peak']:+.2f} %, at the end "
        f"{100 * s['volumetric_strain_end']:+.2f} % ({s['volume_change']})",
        f"strain rate {s['strain_rate']:.3g} 1/s, inertial number {s['inertial_number']:.2e}, dt {s['dt']:.3e} s, "
        f"steps {s['steps_consolidation']} + {s['steps_compression']}",
        f"servo |sigma_3 - target|/target (sigma_3 the lateral walls' mean): max {s['servo_max_relative_error']:.4f}, "
        f"mean {s['servo_mean_relative_error']:.4f} over the CSV rows; one wall alone: max "
        f"{s['servo_max_wall_relative_error']:.4f}",
        f"wall clock: specimen {s.get('generation_wall_clock_s', 0.0):.0f} s, consolidation "
        f"{s['wall_clock_consolidation_s']:.0f} s, compression {s['wall_clock_compression_s']:.0f} s, total "
        f"{s['wall_clock_total_s']:.0f} s",
    ]) + "\n"


def plot_run(data, path, title):
    """q and ε_v against ε₁ (compression and contraction positive)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    e1 = 100 * data["axial_strain"]
    fig, axes = plt.subplots(2, 1, figsize=(6.4, 6.4), sharex=True)
    axes[0].plot(e1, data["deviator_stress"] / 1e3)
    axes[0].set_ylabel("deviator stress q = σ₁ − σ₃ [kPa]")
    axes[1].plot(e1, 100 * data["volumetric_strain"])
    axes[1].axhline(0.0, color="0.6", lw=0.8)
    axes[1].set_ylabel("volumetric strain ε_v [%] (contraction +)")
    axes[1].set_xlabel("axial strain ε₁ [%]")
    axes[0].set_title(title)
    for ax in axes:
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
