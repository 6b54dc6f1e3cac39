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

import math
from pathlib import Path

import numpy as np

from cosim.lab.run import LabTest, Loading, check_resume, grain_sizes, run_lab_test
from cosim.outputs import is_root
from cosim.specimen import SpecimenBox, check_grain_time_step, lab_specimen, read_lab_inputs

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
    if resume:
        check_resume(case_path, out_dir, TriaxialTest, "triaxial")
    built, r_min = read_lab_inputs(case, case_path, tx.size, tx.size)
    mats, sand, _, _ = materials(case)
    check_grain_time_step(case, case_path, mats, sand, r_min, built.get("shapes"), built.get("packing"))
    return built


def make_specimen(case, built, out_dir, cache=None, comm=None):
    """The specimen in the L × L cell, generated to the height L or read from its file;
    returns (positions, radii, height, info); collective with ``comm``."""
    tx = case.triaxial
    return lab_specimen(case, built, SpecimenBox(tx.size, tx.size, tx.size, *materials(case)), out_dir, cache, comm)


# --------------------------------------------------------------------------- the cell
class TriaxialTest(LabTest):
    """Engine + six walls + the servo of the three moving walls (module docstring, steps 2–4),
    run by :func:`cosim.lab.run.run_lab_test`."""

    SERVO_STATE = ("stiffness", "stiffness_step", "v_integral")
    PHASE, STATE_FILE, COLUMNS, SAMPLED = "compression", STATE, COLUMNS, 3

    def __init__(self, case, engine):
        self.case, self.tx = case, case.triaxial
        mats, sand, wall, _ = materials(case)
        self.young_grain, self.young_wall = mats[sand].young, mats[wall].young
        self.density = mats[sand].density
        self.engine = engine
        self.radii, self.grain_radii, self.solid_volume, self.d50 = grain_sizes(engine)  # collective
        self.rate = strain_rate_of(self.tx, self.d50, self.density)
        self.max_velocity = self.tx.servo_max_velocity or 2.0 * self.rate * self.tx.size
        self.stiffness = [0.0, 0.0, 0.0]
        self.stiffness_step = None
        self.v_integral = [0.0, 0.0, 0.0]

    @classmethod
    def build(cls, case, specimen, comm=None):
        from cosim.lab.cubical_box import box_walls
        from de_domain import Engine
        mats, sand, wall, _ = materials(case)
        L = case.triaxial.size
        particles, clumps = specimen.bodies(mats, sand)
        dem = case.dem
        engine = Engine(particles, mats, walls=box_walls(L, L, specimen.height, wall), contact_law=dem.contact_law,
                        gravity=dem.gravity, dt=case.time.dt, safety_factor=case.time.safety_factor,
                        local_damping=dem.local_damping, viscous_damping=dem.viscous_damping, comm=comm,
                        clumps=clumps)
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

    # ---------------------------------------------------------------- 4. the compression (cosim.lab.run)
    specimen = staticmethod(make_specimen)

    @classmethod
    def restored(cls, case, engine, state):
        test = cls(case, engine)
        for k in cls.SERVO_STATE:
            setattr(test, k, state[k])
        return test

    def saved_state(self):
        return {k: getattr(self, k) for k in self.SERVO_STATE}

    def describe(self, height):
        size = self.tx.size
        return (f"cell {size * 1e3:.1f} x {size * 1e3:.1f} x {height * 1e3:.2f} mm, {self.grains_text()} "
                f"(d50 = {self.d50 * 1e3:.2f} mm), dt = {self.engine.dt:.3e} s")

    def start_state(self):
        lengths = self.lengths()
        return {"height0": float(lengths[2]), "volume0": float(np.prod(lengths))}

    def plan(self, loop, out_dir, resume):
        tx, rate = self.tx, self.rate
        self.velocity = rate * loop["height0"]
        # the ramp from 2 % of the rate over ramp_strain takes ln(50) ramp_strain / rate
        total_steps = loop["consolidation_steps"] + int(math.ceil(
            (tx.axial_strain + (math.log(50.0) - 1.0) * tx.ramp_strain) / (rate * self.engine.dt)))
        return Loading(tx.axial_strain, total_steps, tx.rows,
                       f"compressing at eps_dot = {rate:.4g} 1/s (top wall {self.velocity:.4g} m/s, inertial number "
                       f"{self.inertial_number():.2e}) to eps_1 = {tx.axial_strain}: "
                       f"about {total_steps - loop['consolidation_steps']} steps")

    def inertial_number(self):
        return self.rate * self.d50 * math.sqrt(self.density / self.tx.cell_pressure)

    def measure(self, loop):
        """ε₁ = (H₀ − H)/H₀."""
        return (loop["height0"] - self.lengths()[2]) / loop["height0"]

    def advance(self, loop):
        tx = self.tx
        ramp = min(1.0, max(0.02, self.measure(loop) / tx.ramp_strain)) if tx.ramp_strain > 0 else 1.0
        self.step(axial_velocity=self.velocity * ramp)

    def sample(self):
        return self.stresses()

    def row(self, means, loop):
        """The wall stresses averaged over a row's updates, the strains and the state now."""
        from de_domain.diagnostics import coordination_number, unbalanced_force_ratio
        sx, sy, s1 = means
        s3 = 0.5 * (sx + sy)
        lengths = self.lengths()
        e1 = (loop["height0"] - lengths[2]) / loop["height0"]
        ev = (loop["volume0"] - float(np.prod(lengths))) / loop["volume0"]
        return [self.engine.time, e1, ev, s1, sx, sy, s3, s1 - s3, (s1 + 2.0 * s3) / 3.0, (s1 - s3) / (s1 + s3),
                self.void_ratio(), unbalanced_force_ratio(self.engine), coordination_number(self.engine),
                self.engine.step_count]

    def after_update(self, value, loop):
        """Nothing: the triaxial test draws its pictures at the end."""

    def report(self, data, loop, out_dir):
        tx = self.tx
        summary = summarize(data, tx.residual_fraction)
        summary.update({"size": tx.size, "cell_pressure": tx.cell_pressure, "strain_rate": self.rate,
                        "inertial_number": self.inertial_number(), **servo_errors(data, tx.cell_pressure)})
        plot_run(data, out_dir / "triaxial.png", f"{self.case.case.name}: σ₃ = {tx.cell_pressure / 1e3:g} kPa")
        return summary

    def summary_text(self, summary):
        return summary_text(summary)


# --------------------------------------------------------------------------- the run
def run(prepared, specimen_cache=None):
    """The test; under ``mpirun -n N`` the DEM is spread over all ranks."""
    run_lab_test(prepared, TriaxialTest, specimen_cache)


def strain_rate_of(tx, d50, density):
    """ε̇: ``strain_rate``, or from the inertial number I = ε̇ d₅₀ √(ρ/σ₃)."""
    return tx.strain_rate or tx.inertial_number / (d50 * math.sqrt(density / tx.cell_pressure))


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
