"""Case kind ``direct_shear``: the direct shear test of the thesis, Ch. 4 (docs/design.md §3).

The run, top to bottom:

1. **Specimen** — a sieve curve (preset or custom, scaled, truncated) gives grains of
   total volume V_s = L² h / (1 + e_target); multi-layer under-compaction or radius
   expansion (``de_domain.deposition``) builds the specimen in the L × L box; it is
   saved as ``specimen.npz`` (or loaded from ``[specimen] file``).
2. **Shear box** — the box is split at h/2 into two facet-mesh halves with
   frictionless side walls, a rough bottom plane and a rough top plate
   (``cosim.lab.shear_box``); grains get their real density (no mass scaling here).
3. **Consolidation** — the servo moves the top plate until σ_n = F_z / A is within
   ``consolidation_tolerance`` of the target and the unbalanced force ratio is low.
4. **Shearing** — the upper half and the top plate move in +x at the shear velocity
   (ramped over ``ramp_distance``), the servo holding σ_n = F_z / A_c, until
   δ = ``shear_distance``. A CSV row is written every ``shear_distance / rows`` with
   values averaged over the steps since the previous row.
   The servo is the PFC-style proportional law of ``cosim.lab.shear_box.servo_velocity``
   plus a small integral term (``servo_integral``), so σ_n does not lag while the
   specimen dilates or contracts at a steady rate. It updates the plate velocity every
   ``servo_interval`` steps (one compiled DEM run in between), with Δt × that interval
   in its law; CSV values are averaged over the updates since the previous row.
5. **Report** — ``summary.json``/``summary.txt`` (peak and residual τ/σ_n and friction
   angles, volume change, inertial number, servo error), PNG plots.

Measured quantities (``series.csv``):
  * τ = F_x / A_c with F_x the force the grains exert on the moving half (upper side
    walls + top plate), A_c = L (L − δ); ``shear_stress_lower`` is the same from the
    fixed half's reaction, a check;
  * σ_n = F_z(top plate) / A_c (the servo holds this);
  * vertical displacement of the top plate since the end of consolidation (up = +);
  * void ratio of the whole sample e = L² z_plate / V_s − 1 and of two measuring
    spheres at the sample centre (radii 0.45 h and 0.20 h; exact lens volumes);
  * Love–Weber stress (compression +) of a slab of thickness b around the split plane
    over the overlap x ∈ [δ, L]: its σ_zz and σ_xz compare with σ_n and τ;
  * unbalanced force ratio and coordination number;
  * ``plate_shear_force``: the top plate's own share of F_x (N), which τ counts (codes that
    leave the plate out compare with τ − this / A_c), and ``plate_contact_stiffness``: Σ k_n
    of the plate's contacts (N/m), which the stiffness servo divides by.

Servo laws (``direct_shear.servo``): ``stiffness`` (above; default) or ``fixed_gain``, the
thesis's YADE script's v = gain (σ − σ_n)/σ_n with ``|v| ≤ servo_max_velocity``
(``cosim.lab.shear_box.fixed_gain_velocity``). The summary names the law, the gain used and
the mean plate contact stiffness.
"""
from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from cosim.lab.run import LabTest, Loading, check_resume, grain_sizes, run_lab_test
from cosim.outputs import is_root
from cosim.specimen import SpecimenBox, check_grain_time_step, lab_specimen, read_lab_inputs

SHEAR_STATE = "shear_state.json"
SHEAR_START = "shear_start.npz"  # every grain's position when shearing began (the shear-band pictures)
# averaged over the servo updates of a CSV row
SUMS = ("shear_stress", "normal_stress", "shear_stress_lower", "plate_shear_force", "plate_contact_stiffness")
COLUMNS = ["time", "shear_displacement", "shear_stress", "normal_stress", "vertical_displacement",
           "void_ratio", "void_ratio_sphere_045h", "void_ratio_sphere_020h", "shear_stress_lower",
           "lw_normal_stress", "lw_shear_stress", "unbalanced_force_ratio", "coordination_number",
           "shear_velocity", "step", "plate_shear_force", "plate_contact_stiffness"]


# --------------------------------------------------------------------------- inputs
def materials(case):
    """de_domain Materials from [dem.materials] (as the ``dem`` app) and the ids of the
    grains, side walls and plates."""
    from cosim.apps.dem import materials_of
    ds = case.direct_shear
    return materials_of(case.dem, ds.sand_material, ds.side_wall_material, ds.plate_material)


def prepare(case, case_path, out_dir, resume):
    """Everything that can fail on input, before any computation, on rank 0 (where the
    specimen is made): the packing file or the sieve curve, the checkpoint to resume from, and a
    given time step against the critical step of the smallest grain. None elsewhere."""
    if not is_root():
        return None
    ds = case.direct_shear
    out_dir = Path(out_dir)
    if resume:
        check_resume(case_path, out_dir, ShearTest, "shear")
    built, r_min = read_lab_inputs(case, case_path, ds.box_length, ds.box_length)
    mats, sand, _, _ = materials(case)
    check_grain_time_step(case, case_path, mats, sand, r_min, built.get("shapes"), built.get("packing"))
    return built


# --------------------------------------------------------------------------- 1. specimen
def make_specimen(case, built, out_dir, cache=None, comm=None):
    """Load or generate the specimen in the L × L shear box (cosim.specimen.make_specimen);
    returns (positions, radii, height, info dict); collective with ``comm``."""
    ds = case.direct_shear
    box = SpecimenBox(ds.box_length, ds.box_length, ds.sample_height, *materials(case))
    return lab_specimen(case, built, box, out_dir, cache, comm)


# --------------------------------------------------------------------------- 2. shear box
class ShearTest(LabTest):
    """Engine + split box + servo for one direct shear test (steps 2–4 of the module docstring),
    run by :func:`cosim.lab.run.run_lab_test`."""

    SERVO_STATE = ("stiffness", "stiffness_step", "v_integral", "shear_velocity")
    PHASE, STATE_FILE, COLUMNS, SAMPLED = "shear", SHEAR_STATE, COLUMNS, len(SUMS)

    def __init__(self, case, engine, height, x0=None):
        """``engine``: walls [bottom, top plate], facets [lower half, upper half] (see
        :meth:`build`); ``height``: specimen height before consolidation; ``x0``: the
        upper half's vertex x at zero shear (default: now)."""
        self.case = case
        ds = self.ds = case.direct_shear
        mats, sand, wall, plate = materials(case)
        self.young_grain, self.young_plate = mats[sand].young, mats[plate].young
        self.density = mats[sand].density
        self.L = ds.box_length
        self.geometry = self.box_geometry(case, height)
        self.engine = engine
        self.bottom, self.plate = engine.walls
        self.lower, self.upper = engine.facets
        self.radii, self.grain_radii, self.solid_volume, self.d50 = grain_sizes(engine)  # collective
        self.height0 = height
        self.x0 = self.upper.vertices[:, 0].copy() if x0 is None else np.asarray(x0, float)
        self.stiffness = 0.0
        self.stiffness_step = None
        self.v_integral = 0.0
        self.shear_velocity = 0.0

    @staticmethod
    def box_geometry(case, height):
        """The split box for a specimen of ``height``; lips one shear distance + 5 % L long."""
        from cosim.lab.shear_box import ShearBoxGeometry
        ds = case.direct_shear
        return ShearBoxGeometry(ds.box_length, height, lip_length=ds.shear_distance + 0.05 * ds.box_length)

    @classmethod
    def build(cls, case, specimen, comm=None):
        """The specimen in the split box (module docstring, step 2); with ``comm``, the
        DEM spread over its ranks (collective)."""
        from de_domain import Engine, FacetMesh, PlaneWall
        mats, sand, wall, plate = materials(case)
        height = specimen.height
        geometry = cls.box_geometry(case, height)
        particles, clumps = specimen.bodies(mats, sand)
        facets = [FacetMesh(*geometry.lower_half(), material=wall), FacetMesh(*geometry.upper_half(), material=wall)]
        walls = [PlaneWall((0, 0, 0), (0, 0, 1), material=plate), PlaneWall((0, 0, height), (0, 0, -1), material=plate)]
        dem = case.dem
        engine = Engine(particles, mats, walls=walls, facets=facets, contact_law=dem.contact_law, gravity=dem.gravity,
                        dt=case.time.dt, safety_factor=case.time.safety_factor, local_damping=dem.local_damping,
                        viscous_damping=dem.viscous_damping, comm=comm, clumps=clumps)
        return cls(case, engine, height)

    # ---------------------------------------------------------------- measurements
    @property
    def displacement(self):
        return float(np.mean(self.upper.vertices[:, 0] - self.x0))

    def area(self):
        from cosim.lab.shear_box import corrected_area
        return corrected_area(self.L, self.displacement)

    def normal_stress(self):
        return float(self.plate.force[2]) / self.area()

    def shear_stress(self):
        """τ from the moving half: the grains push it back (−x), hence the sign."""
        return -float(self.upper.force[0] + self.plate.force[0]) / self.area()

    def plate_shear_force(self):
        """The top plate's own share of the shear force (N): the grains drag it back (−x)."""
        return -float(self.plate.force[0])

    def shear_stress_lower(self):
        return float(self.lower.force[0] + self.bottom.force[0]) / self.area()

    def void_ratio(self):
        return self.L * self.L * float(self.plate.point[2]) / self.solid_volume - 1.0

    def sphere_void_ratios(self):
        from de_domain.diagnostics import SphereRegion, void_ratio
        h = self.height0
        centre = (0.5 * self.L + 0.5 * self.displacement, 0.5 * self.L, 0.5 * h)
        return (void_ratio(self.engine, SphereRegion(centre, 0.45 * h)),
                void_ratio(self.engine, SphereRegion(centre, 0.20 * h)))

    def love_weber_slab(self):
        """(σ_zz, σ_xz) of the slab around the split plane over the overlap (compression +)."""
        from de_domain.diagnostics import BoxRegion, love_weber_stress
        b = self.ds.band_thickness or 2.0 * self.d50
        zs = self.geometry.split_height
        region = BoxRegion((self.displacement, 0.0, zs - 0.5 * b), (self.L, self.L, zs + 0.5 * b))
        s = love_weber_stress(self.engine, region)
        return float(s[2, 2]), float(0.5 * (s[0, 2] + s[2, 0]))

    # ---------------------------------------------------------------- servo step
    def update_stiffness(self):
        from cosim.lab.shear_box import plate_contact_stiffness
        self.stiffness = plate_contact_stiffness(self.engine.wall_contact_particles(1), self.radii,
                                                 self.young_grain, self.young_plate)

    def step(self, target):
        """``servo_interval`` DEM steps with the plate velocity from the servo law (σ of
        the last step); the contact stiffness of the plate is refreshed every ≥ 25 steps."""
        from cosim.lab.shear_box import fixed_gain_velocity, servo_velocity
        ds = self.ds
        if self.stiffness_step is None or self.engine.step_count - self.stiffness_step >= 25:
            self.update_stiffness()
            self.stiffness_step = self.engine.step_count
        if ds.servo == "fixed_gain":
            vz = fixed_gain_velocity(self.normal_stress(), target, ds.servo_fixed_gain or ds.servo_max_velocity,
                                     ds.servo_max_velocity)
        else:
            vz = servo_velocity(self.normal_stress(), target, self.area(), self.stiffness,
                                self.engine.dt * ds.servo_interval, ds.servo_gain, ds.servo_max_velocity)
            if self.stiffness > 0.0:  # integral action: no steady lag while the specimen dilates or contracts
                self.v_integral = float(np.clip(self.v_integral + ds.servo_integral * vz,
                                                -ds.servo_max_velocity, ds.servo_max_velocity))
            vz = float(np.clip(vz + self.v_integral, -ds.servo_max_velocity, ds.servo_max_velocity))
        self.plate.velocity = np.array([self.shear_velocity, 0.0, vz])
        self.upper.velocity = np.array([self.shear_velocity, 0.0, 0.0])
        from cosim.apps.dem import advance
        advance(self.engine, ds.servo_interval)

    # ---------------------------------------------------------------- 3. consolidation
    def consolidate(self, log):
        from de_domain.diagnostics import unbalanced_force_ratio
        ds = self.ds
        target = ds.normal_stress
        window = []
        per_check = max(1, 100 // ds.servo_interval)  # updates per check (~100 steps)
        n = 0
        while n < ds.max_consolidation_steps:
            self.step(target)
            n += ds.servo_interval
            window.append(self.normal_stress())
            if len(window) % per_check == 0:
                mean = float(np.mean(window[-per_check:]))
                if abs(mean - target) < ds.consolidation_tolerance * target:
                    uf = unbalanced_force_ratio(self.engine)
                    if uf < ds.consolidation_unbalanced_force:
                        log(f"consolidated to σ_n = {mean:.4g} Pa in {n} steps (unbalanced force {uf:.3g}), "
                            f"e = {self.void_ratio():.4f}")
                        return n
        log(f"consolidation stopped after {ds.max_consolidation_steps} steps: σ_n = {self.normal_stress():.4g} Pa, "
            f"unbalanced force {unbalanced_force_ratio(self.engine):.3g}")
        return n

    # ---------------------------------------------------------------- 4. the shearing (cosim.lab.run)
    specimen = staticmethod(make_specimen)

    @classmethod
    def restored(cls, case, engine, state):
        test = cls(case, engine, state["height0"], state["x0"])
        for k in cls.SERVO_STATE:
            setattr(test, k, state[k])
        return test

    def saved_state(self):
        return {**{k: getattr(self, k) for k in self.SERVO_STATE}, "x0": self.x0.tolist(), "height0": self.height0}

    def describe(self, height):
        ds = self.ds
        return (f"shear box {ds.box_length * 1e3:.0f} x {ds.box_length * 1e3:.0f} mm, h = {height * 1e3:.2f} mm, "
                f"{self.grains_text()} (d50 = {self.d50 * 1e3:.2f} mm), "
                f"dt = {self.engine.dt:.3e} s")

    def resumed_text(self):
        return f", δ = {self.displacement * 1e3:.3f} mm"

    def start_state(self):
        return {"z0": float(self.plate.point[2]), "servo_errors": []}

    def plan(self, loop, out_dir, resume):
        from cosim.lab.shear_box import inertial_number, velocity_for_inertial_number
        ds = self.ds
        self.velocity = ds.shear_velocity or velocity_for_inertial_number(ds.inertial_number, self.height0, self.d50,
                                                                          self.density, ds.normal_stress)
        self.inertial = inertial_number(self.velocity, self.height0, self.d50, self.density, ds.normal_stress)
        self.band_pictures = _band_pictures(self.case, out_dir, loop, self, resume)
        # the ramp from 2 % of v over ramp_distance takes ln(50) ramp_distance / v
        total_steps = loop["consolidation_steps"] + int(math.ceil(
            (ds.shear_distance + (math.log(50.0) - 1.0) * ds.ramp_distance) / (self.velocity * self.engine.dt)))
        return Loading(ds.shear_distance, total_steps, ds.rows,
                       f"shearing at v = {self.velocity:.4g} m/s (inertial number I = {self.inertial:.2e}) to "
                       f"δ = {ds.shear_distance * 1e3:.2f} mm: about {total_steps - loop['consolidation_steps']} steps")

    def measure(self, loop):
        return self.displacement

    def advance(self, loop):
        ds = self.ds
        ramp = min(1.0, max(0.02, self.displacement / ds.ramp_distance)) if ds.ramp_distance > 0 else 1.0
        self.shear_velocity = self.velocity * ramp
        self.step(ds.normal_stress)

    def sample(self):
        return (self.shear_stress(), self.normal_stress(), self.shear_stress_lower(), self.plate_shear_force(),
                self.stiffness)

    def row(self, means, loop):
        from de_domain.diagnostics import coordination_number, unbalanced_force_ratio
        e1, e2 = self.sphere_void_ratios()
        lw_zz, lw_xz = self.love_weber_slab()
        ds, delta = self.ds, self.displacement
        row = [self.engine.time, delta, means[0], means[1], float(self.plate.point[2]) - loop["z0"],
               self.void_ratio(), e1, e2, means[2], lw_zz, lw_xz, unbalanced_force_ratio(self.engine),
               coordination_number(self.engine), self.shear_velocity, self.engine.step_count, means[3], means[4]]
        if delta > ds.ramp_distance:
            loop["servo_errors"].append(abs(row[3] - ds.normal_stress) / ds.normal_stress)
        return row

    def after_update(self, value, loop):
        self.band_pictures(value)  # collective when distributed

    def report(self, data, loop, out_dir):
        from cosim.lab.shear_box import corrected_area
        from cosim.lab.shear_report import plot_run, summarize
        ds, servo_errors = self.ds, loop["servo_errors"]
        summary = summarize(data["shear_displacement"], data["shear_stress"], data["normal_stress"],
                            data["vertical_displacement"], ds.residual_fraction)
        after = data["shear_displacement"] > ds.ramp_distance
        ratio = lambda a, b: float(np.mean(a[after]) / np.mean(b[after]))  # noqa: E731
        stiffness = np.mean(data["plate_contact_stiffness"][after])
        summary.update({
            "sample_height": self.height0, "normal_stress": ds.normal_stress, "shear_velocity": self.velocity,
            "inertial_number": self.inertial,
            "void_ratio_sphere_045h_end": float(data["void_ratio_sphere_045h"][-1]),
            "void_ratio_sphere_020h_end": float(data["void_ratio_sphere_020h"][-1]),
            "servo_max_relative_error": float(max(servo_errors)) if servo_errors else None,
            "servo_mean_relative_error": float(np.mean(servo_errors)) if servo_errors else None,
            "servo": ds.servo,
            "servo_gain": ds.servo_gain if ds.servo == "stiffness" else ds.servo_fixed_gain or ds.servo_max_velocity,
            "servo_gain_unit": "fraction of the stress error per update" if ds.servo == "stiffness"
                               else "m/s per unit relative stress error",
            "plate_contact_stiffness_mean": float(stiffness),
            "servo_fixed_gain_stable_below": float(2.0 * ds.normal_stress * np.mean(corrected_area(
                ds.box_length, data["shear_displacement"][after])) / (stiffness * self.engine.dt * ds.servo_interval)),
            "plate_shear_force_over_total": float(np.mean(data["plate_shear_force"][after]) / np.mean(
                data["shear_stress"][after] * corrected_area(ds.box_length, data["shear_displacement"][after]))),
            "love_weber_normal_over_wall": ratio(data["lw_normal_stress"], data["normal_stress"]),
            "love_weber_shear_over_wall": ratio(np.abs(data["lw_shear_stress"]), data["shear_stress"]),
            "shear_lower_over_upper": ratio(data["shear_stress_lower"], data["shear_stress"]),
            "shear_band": loop["shear_band"],
        })
        plot_run(data, out_dir, f"{self.case.case.name}: σ_n = {ds.normal_stress / 1e3:.0f} kPa")
        return summary

    def summary_text(self, summary):
        return summary_text(summary)


# --------------------------------------------------------------------------- the run
def run(prepared, specimen_cache=None):
    """The test. Under ``mpirun -n N`` (N > 1) the DEM of the specimen generation, the
    consolidation and the shear is spread over all ranks (bit-identical to one rank)."""
    run_lab_test(prepared, ShearTest, specimen_cache)


def summary_text(s):
    servo = s["servo_max_relative_error"]
    return "\n".join([
        f"grains {s['grains']}, d50 {s['d50'] * 1e3:.2f} mm, h {s['sample_height'] * 1e3:.2f} mm, "
        f"sigma_n {s['normal_stress'] / 1e3:.0f} kPa",
        f"void ratio: {_initial_void_ratio(s)}, consolidated "
        f"{s['void_ratio_consolidated']:.4f}, end {s['void_ratio_end']:.4f} "
        f"(sphere 0.45h {s['void_ratio_sphere_045h_end']:.4f}, sphere 0.20h {s['void_ratio_sphere_020h_end']:.4f})",
        f"peak tau/sigma_n {s['peak_stress_ratio']:.3f} (phi_peak {s['peak_friction_angle_deg']:.1f} deg) at "
        f"delta {s['peak_shear_displacement'] * 1e3:.2f} mm; residual {s['residual_stress_ratio']:.3f} "
        f"(phi_res {s['residual_friction_angle_deg']:.1f} deg)",
        f"vertical displacement at the end {s['vertical_displacement_end'] * 1e3:+.3f} mm ({s['volume_change']}), "
        f"softening: {s['softening']}",
        f"shear velocity {s['shear_velocity']:.3g} m/s, inertial number {s['inertial_number']:.2e}, "
        f"dt {s['dt']:.3e} s, steps {s['steps_consolidation']} + {s['steps_shear']}",
        f"servo |sigma - sigma_n|/sigma_n: max {servo if servo is not None else float('nan'):.4f} over the CSV rows; "
        f"Love-Weber/wall: normal {s['love_weber_normal_over_wall']:.3f}, shear {s['love_weber_shear_over_wall']:.3f}; "
        f"lower/upper shear force {s['shear_lower_over_upper']:.3f}",
        f"servo law {s['servo']}, gain {s['servo_gain']:.3g} ({s['servo_gain_unit']}); plate contact stiffness "
        f"{s['plate_contact_stiffness_mean']:.4g} N/m (mean); the top plate carries "
        f"{100 * s['plate_shear_force_over_total']:.1f} % of the shear force",
        *(f"shear band at delta {b['shear_displacement'] * 1e3:.2f} mm: thickness {b['thickness'] * 1e3:.2f} mm "
          f"= {b['thickness_d50']:.1f} d50 (10-90 % of u_x/delta), centred at z = {b['centre_height'] * 1e3:.2f} mm"
          for b in s.get("shear_band", ())),
        f"wall clock: specimen {s.get('generation_wall_clock_s', 0.0):.0f} s, consolidation "
        f"{s.get('wall_clock_consolidation_s', 0.0):.0f} s, shear {s['wall_clock_shear_s']:.0f} s, total "
        f"{s['wall_clock_total_s']:.0f} s (a resumed run counts every process up to its last checkpoint)",
    ]) + "\n"


def _initial_void_ratio(s):
    e = s.get("void_ratio_generated")
    if s.get("source") in ("under_compaction", "radius_expansion"):
        return f"generated {e:.4f}"
    return f"from {s.get('source')} {e:.4f}" if e is not None else f"from {s.get('source')} (not stored there)"


def _band_pictures(case, out_dir, loop, test, resume):
    """Shear-band pictures and thicknesses at ``direct_shear.band_pictures``
    (``cosim.lab.shear_band``). Every grain's position when shearing begins is kept in
    ``shear_start.npz`` for a resumed run; the number of pictures made so far is in
    ``loop["next_band_picture"]`` and their records in ``loop["shear_band"]`` (both
    checkpointed). Returns ``write(delta)``, collective when the engine is distributed."""
    from cosim.lab.shear_band import band_record, measure_band, plot_section
    ds = case.direct_shear
    targets = sorted(ds.band_pictures or (ds.shear_distance / 3.0, ds.shear_distance))
    path = Path(out_dir) / SHEAR_START
    if resume:
        if "next_band_picture" not in loop:  # a checkpoint written before the pictures existed: none made
            loop.update(next_band_picture=len(targets), shear_band=[])
        start = np.load(path)["position"] if is_root() and loop["next_band_picture"] < len(targets) else None
    else:
        start = test.engine.global_particles().pos.copy()  # collective when distributed
        if is_root():
            tmp = path.with_name(path.stem + ".tmp.npz")
            np.savez(tmp, position=start)
            tmp.replace(path)
        loop.update(next_band_picture=0, shear_band=[])

    def write(delta):
        while loop["next_band_picture"] < len(targets) and delta >= targets[loop["next_band_picture"]] - 1e-12:
            loop["next_band_picture"] += 1
            now = test.engine.global_particles()  # collective when distributed
            if not is_root():
                continue
            before = SimpleNamespace(pos=start)
            split = test.geometry.split_height
            fit, profile = measure_band(before, now, delta, test.L, test.d50, split)
            loop["shear_band"].append(band_record(fit, delta, test.d50))
            box = {"box_length": test.L, "split_height": split, "delta": delta,
                   "plate_height": float(test.plate.point[2])}
            plot_section(Path(out_dir) / f"shear_band_{delta * 1e3:.1f}mm.png", before, now, box, fit, profile,
                         f"{case.case.name}: σ_n = {ds.normal_stress / 1e3:.0f} kPa, δ = {delta * 1e3:.2f} mm, "
                         f"shear band {fit.thickness * 1e3:.1f} mm = {fit.thickness / test.d50:.1f} d50")
    return write
