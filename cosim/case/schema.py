"""The case file's schema: one pydantic model per TOML table, every field with its type, unit
(in its description) and allowed range; unknown keys are errors (``extra="forbid"``).
``cosim schema`` prints it all (:mod:`cosim.schema_doc`); :mod:`cosim.case.validation` adds the
rules between fields that a field's own range cannot state.
"""
from __future__ import annotations

from typing import Annotated, Literal, Optional

from pydantic import BaseModel, ConfigDict, Field, field_validator

Vec3 = Annotated[list[float], Field(min_length=3, max_length=3)]


class Section(BaseModel):
    """A TOML table of a case (or calibration) file."""
    # strict: TOML has types, so "yes" is not a bool and "3" not a number; no NaN or inf
    # anywhere (a float key accepts an integer, as TOML users write 1 for 1.0)
    model_config = ConfigDict(extra="forbid", validate_assignment=True, strict=True, allow_inf_nan=False)


# --------------------------------------------------------------------------- case
class CaseInfo(Section):
    name: str = Field(
        pattern=r"^[A-Za-z0-9][A-Za-z0-9._-]{0,99}$",
        description="case name: letters, digits, '.', '_', '-' (at most 100, no path); outputs go to runs/out/<name>/")
    kind: Literal["dem", "direct_shear", "triaxial", "fe", "coupled", "footing", "embedded"] = Field(
        description="what to run: 'dem' (a DEM simulation of particles and walls), "
                    "'direct_shear' (specimen generation + the direct shear test, docs/design.md §3), "
                    "'triaxial' (specimen generation + a drained triaxial compression test, docs/design.md §3.10), "
                    "'fe' (the explicit mixed u-p solid on a gmsh mesh, docs/design.md §4), "
                    "'coupled' (FE solid and DEM particles through an interface, docs/design.md §5), "
                    "'footing' (a rigid strip footing pushed into a DEM zone embedded in an FE soil block, "
                    "or into an all-DEM block of the same size, docs/design.md §7), "
                    "'embedded' (your own gmsh model: FE volumes, DEM zones of any shape, rigid bodies; or its "
                    "all-DEM twin, docs/guide/own-geometry.md)")
    seed: int = Field(default=12345, ge=0, description="random seed (particle generation) [-]")


class TimeSection(Section):
    duration: Optional[float] = Field(default=None, gt=0, description="simulated time [s] (give duration or steps)")
    steps: Optional[int] = Field(default=None, gt=0, description="number of time steps [-] (give duration or steps)")
    dt: Optional[float] = Field(default=None, gt=0, description="time step [s]; default safety_factor x critical step")
    safety_factor: float = Field(default=0.3, gt=0, le=0.5, description="fraction of the critical time step [-]")
    fe_safety_factor: Optional[float] = Field(
        default=None, gt=0, le=0.9,
        description="the FE's step as a fraction of its exact limit 2/omega_max (power iteration on M^-1 K; kinds "
                    "coupled and embedded, displacement formulation); unset: safety_factor x the cell estimate "
                    "min h/c_p, which a thin stiff structure's cells can make the run's step [-]")


class OutputSection(Section):
    interval: float = Field(
        default=0.0, ge=0,
        description="time between CSV rows and VTK frames [s]; 0 = 20 frames per run")
    vtk: bool = Field(default=True, description="write particles/walls as VTU + PVD for ParaView")
    checkpoint_interval: float = Field(default=600.0, gt=0, description="wall-clock time between checkpoints [s]")
    progress_interval: float = Field(default=2.0, gt=0, description="wall-clock time between progress lines [s]")


# --------------------------------------------------------------------------- dem
class DemMaterial(Section):
    name: str = Field(min_length=1, description="material name, referenced by particles and walls")
    density: float = Field(gt=0, description="solid density [kg/m^3]")
    young: float = Field(gt=0, description="Young's modulus E; linear law k_n = 2 E r* (docs/design.md §2.3) [Pa]")
    poisson: float = Field(default=0.25, ge=0, lt=0.5, description="Poisson's ratio (Hertz-Mindlin) [-]")
    friction: float = Field(default=0.5, ge=0, description="Coulomb friction coefficient mu [-]")
    restitution: float = Field(
        default=0.5, gt=0, le=1,
        description="normal restitution coefficient e [-]; 1 turns the normal dashpot off (elastic impacts)")
    stiffness_ratio: float = Field(default=1.5, gt=0, description="kappa = k_n / k_t [-]")
    rolling_stiffness: float = Field(default=0.0, ge=0, description="beta_r: k_r = beta_r k_t rbar^2 [-]")
    rolling_friction: float = Field(default=0.0, ge=0, description="eta_r: |M_r| <= eta_r f_n rbar [-]")


class DemParticles(Section):
    source: Literal["cloud", "file"] = Field(
        description="'cloud': random non-overlapping spheres in a box; 'file': a packing file")
    file: Optional[str] = Field(
        default=None,
        description="packing (.npz, or text 'x y z r' per line), relative to the case file")
    count: Optional[int] = Field(default=None, gt=0, description="number of spheres for source='cloud' [-]")
    box: Optional[list[Vec3]] = Field(
        default=None, min_length=2, max_length=2,
        description="[[xmin,ymin,zmin],[xmax,ymax,zmax]] of the cloud [m]")
    radius: Optional[list[float]] = Field(
        default=None, min_length=2, max_length=2,
        description="[r_min, r_max], uniform radii for source='cloud' [m]")
    material: str = Field(description="material name of these spheres")
    velocity: Vec3 = Field(default=[0.0, 0.0, 0.0], description="initial velocity of every sphere [m/s]")
    grains: Literal["spheres", "clumps"] = Field(
        default="spheres",
        description="'spheres', or 'clumps': rigid grains of overlapping spheres shaped as the [[dem.clumps]] "
                    "templates (source='cloud'; count grains, each of an equal-volume radius drawn from radius)")


class DemClumpTemplate(Section):
    members: list[list[float]] = Field(
        min_length=1,
        description="member spheres [[x, y, z, r], ...] of one grain shape, in any length unit (each grain is "
                    "scaled to its drawn size); members must overlap or touch")
    share: float = Field(default=1.0, gt=0, description="relative number of grains of this shape [-]")


class DemWall(Section):
    type: Literal["plane", "facets"] = Field(description="'plane': infinite plane; 'facets': triangle mesh file")
    point: Optional[Vec3] = Field(default=None, description="a point on the plane [m]")
    normal: Optional[Vec3] = Field(default=None, description="plane normal, pointing into the particles [-]")
    file: Optional[str] = Field(
        default=None,
        description="triangle mesh (.stl or gmsh .msh) for type='facets', relative to the case file")
    velocity: Vec3 = Field(default=[0.0, 0.0, 0.0], description="prescribed translation velocity [m/s]")
    material: str = Field(description="material name of the wall")


class DemSection(Section):
    contact_law: Literal["linear", "hertz"] = Field(
        default="linear",
        description="'linear' (Cundall-Strack) or 'hertz' (Hertz-Mindlin)")
    gravity: Vec3 = Field(default=[0.0, 0.0, -9.81], description="gravitational acceleration [m/s^2]")
    local_damping: float = Field(default=0.0, ge=0, lt=1, description="non-viscous background damping alpha_b [-]")
    viscous_damping: float = Field(default=0.0, ge=0, description="viscous background damping alpha_v [1/s]")
    materials: list[DemMaterial] = Field(min_length=1, description="[[dem.materials]] tables")
    particles: Optional[DemParticles] = Field(default=None, description="[dem.particles]: the spheres of a 'dem' case")
    clumps: list[DemClumpTemplate] = Field(
        default_factory=list, description="[[dem.clumps]] grain shapes for [dem.particles] grains = 'clumps'")
    walls: list[DemWall] = Field(default_factory=list, description="[[dem.walls]] tables")


# ---------------------------------------------------------------- specimens and the lab tests (docs/design.md §3)
class SpecimenSection(Section):
    source: Literal["generate", "file"] = Field(
        default="generate",
        description="'generate': build the specimen (method below); 'file': load a packing (.npz or text 'x y z r')")
    file: Optional[str] = Field(default=None, description="packing file for source='file', relative to the case file")
    method: Literal["under_compaction", "radius_expansion"] = Field(
        default="under_compaction",
        description="'under_compaction': multi-layer gravity deposition with a compaction plate (Jiang "
                    "et al. 2003); 'radius_expansion': grow radii in the closed box")
    sieve: str = Field(
        default="thesis_sand",
        description="sieve-curve preset (de_domain.packing.SIEVE_PRESETS), "
                    "unless sieve_diameters/sieve_passing are given")
    sieve_diameters: Optional[list[float]] = Field(
        default=None, min_length=2,
        description="custom sieve curve: increasing sieve sizes [m]")
    sieve_passing: Optional[list[float]] = Field(
        default=None, min_length=2,
        description="custom sieve curve: cumulative mass fraction passing, 0 ... 1 [-]")
    scale: float = Field(
        default=1.0, gt=0, le=100,
        description="scale factor applied to every diameter (thesis: 4) [-]")
    truncate_below: Optional[float] = Field(
        default=None, gt=0,
        description="drop the fines below this (scaled) diameter [m]")
    truncate_above: Optional[float] = Field(
        default=None, gt=0,
        description="drop the grains above this (scaled) diameter [m]")
    grains: Literal["spheres", "clumps"] = Field(
        default="spheres",
        description="'spheres', or 'clumps' (direct_shear, triaxial, embedded, footing): rigid grains of "
                    "overlapping spheres shaped as "
                    "the [[dem.clumps]] templates, drawn by share, each enlarged to its sieve diameter (equal volume), "
                    "in random orientations")
    zone_stress: Literal["expansion", "weight"] = Field(
        default="expansion",
        description="a zone fill's stress at rest (embedded, footing): 'expansion' lifts a lid over a free surface "
                    "off the radius expansion's stress (a closed zone's is let go) and keeps the horizontal stress "
                    "the walls hold; 'weight' lets the expansion's stress go everywhere (the grains shrunk until "
                    "their mean stress is 2 % of their weight's at the zone's bottom) and lets them settle under "
                    "gravity with their material's own friction: a ground laid down under its weight, whose "
                    "release loosens the packing where the expansion pressed it hard. rest_stress.csv gives "
                    "K = sigma_h / sigma_v by depth (the tunnel's all-DEM block: 1.26 and 0.75)")
    void_ratio: float = Field(
        default=0.65, gt=0.3, lt=1.5,
        description="target void ratio e = V_voids/V_solids of the specimen [-]")
    tolerance: float = Field(default=0.01, gt=0, le=0.1, description="allowed |e - target| [-]")
    layers: Optional[int] = Field(
        default=None, ge=1, le=50,
        description="number of layers (under_compaction); default from the target: "
                    "ceil(V_solid / (cloud_solid_fraction * generation volume))")
    undercompaction: float = Field(
        default=0.03, ge=0, le=0.3,
        description="U_1: the first layer is compacted to (1 + U_1) x its nominal thickness, "
                    "U decreasing linearly to 0 at the last layer [-]")
    cloud_solid_fraction: float = Field(
        default=0.2, gt=0.01, le=0.35,
        description="solid fraction of each generated cloud [-]")
    deposition_material: Optional[str] = Field(
        default=None,
        description="a [[dem.materials]] name: the grains' material while the specimen is made (its density, "
                    "young, stiffness_ratio, friction, ...; the deposition_* keys below still override its "
                    "friction and rolling resistance), e.g. the thesis's packing parameters (Table 4.1) "
                    "against its test parameters (App. D); default: the sand's")
    deposition_friction: Optional[float] = Field(
        default=None, ge=0,
        description="particle friction during generation (lowered automatically when the "
                    "plate cannot reach its height); default: the sand's [-]")
    deposition_rolling_friction: Optional[float] = Field(
        default=None, ge=0,
        description="rolling friction eta_r of the grains during generation (|M_r| <= eta_r f_n r; "
                    "lowered with the friction); loose targets need it; default: the sand's [-]")
    deposition_rolling_stiffness: Optional[float] = Field(
        default=None, ge=0,
        description="rolling stiffness beta_r of the grains during generation (k_r = beta_r k_t r^2); "
                    "default: the sand's, or 1 when only deposition_rolling_friction is given [-]")
    density_scale: float = Field(
        default=100.0, ge=1, le=1e4,
        description="mass scaling during generation only: density x this and gravity / this "
                    "(real weights), so dt grows by its square root [-]")
    plate_velocity: float = Field(default=0.3, gt=0, description="speed of the compaction plate [m/s]")
    plate_stress_limit: float = Field(
        default=20e3, gt=0,
        description="plate stress above which the friction is halved to let the layer compact [Pa]")
    friction_reduction: float = Field(
        default=0.5, gt=0, lt=1,
        description="factor on the generation friction each time the plate stalls [-]")
    hold_friction: Optional[float] = Field(
        default=None, ge=0,
        description="grain friction once the plate holds a layer at its height (contact history kept; "
                    "the rolling friction follows in proportion); loose targets: the deposition friction, "
                    "so the layer does not creep below the plate; default: the friction reached [-]")
    local_damping: float = Field(
        default=0.5, ge=0, lt=1,
        description="local (Cundall) damping during generation (the test uses [dem] local_damping) [-]")
    unbalanced_force: float = Field(
        default=0.01, gt=0, le=0.5,
        description="a layer ends when the unbalanced force ratio is below this [-]")
    max_steps_per_layer: int = Field(default=200000, gt=0, description="safety cap on steps per layer [-]")


class LabTestSection(Section):
    """What the direct shear and the triaxial test share: the rate, the servo walls, the
    consolidation before the test, the materials and the residual values."""
    inertial_number: float = Field(
        default=1e-3, gt=0, le=0.1,
        description="target inertial number I = (strain rate) d50 sqrt(rho / sigma), sigma the test's stress, when no "
                    "velocity or rate is given: direct shear v/h and sigma_n, triaxial the axial strain rate and "
                    "sigma_3 [-]")
    servo_gain: float = Field(
        default=0.3, gt=0, le=1,
        description="fraction of the stress error a servo wall (the direct shear's top plate, the triaxial's lateral "
                    "walls) removes per update, scaled by its contact stiffness (PFC-style gain) [-]")
    servo_integral: float = Field(
        default=0.01, ge=0, le=0.2,
        description="integral action: per update the integral velocity grows by this x the proportional one [-]")
    servo_interval: int = Field(
        default=2, ge=1, le=1000,
        description="DEM steps between servo updates; the wall velocity is held in between and the servo law uses "
                    "this x dt [-]")
    consolidation_tolerance: float = Field(
        default=0.01, gt=0, le=0.1,
        description="consolidation ends when every servo-held stress is within this fraction of its target "
                    "(|sigma - sigma_n|/sigma_n, |sigma - sigma_3|/sigma_3) ... [-]")
    consolidation_unbalanced_force: float = Field(
        default=0.02, gt=0, le=0.5, description="... and the unbalanced force ratio is below this [-]")
    sand_material: str = Field(default="sand", description="material name of the grains ([[dem.materials]])")
    plate_material: str = Field(
        default="plate",
        description="material name of the plates: the shear box's top and bottom plates (rough); the triaxial "
                    "generation box's bottom and compaction plate")
    residual_fraction: float = Field(
        default=0.2, gt=0, lt=1,
        description="the residual (triaxial: critical-state) values are the means over this last fraction of the "
                    "shear distance or axial strain [-]")


class DirectShearSection(LabTestSection):
    box_length: float = Field(default=0.06, gt=0, description="inner side L of the square shear box [m]")
    sample_height: float = Field(default=0.025, gt=0, description="specimen height h (box split at h/2) [m]")
    normal_stress: float = Field(
        default=100e3, gt=0, le=10e6,
        description="normal stress sigma_n held by the servo top plate [Pa]")
    shear_distance: float = Field(
        default=0.009, gt=0,
        description="horizontal displacement of the upper half at the end [m] (15 % of L = 9 mm)")
    shear_velocity: Optional[float] = Field(
        default=None, gt=0,
        description="velocity of the upper half [m/s]; default from inertial_number")
    ramp_distance: float = Field(
        default=2e-4, ge=0,
        description="the shear velocity ramps up linearly over this displacement [m]")
    servo: Literal["stiffness", "fixed_gain"] = Field(
        default="stiffness",
        description="servo law of the top plate: 'stiffness' (removes servo_gain of the stress error per update, "
                    "scaled by the plate's contact stiffness, PFC-style, with integral action) or 'fixed_gain' "
                    "(v = servo_fixed_gain x the relative stress error, as the thesis's YADE script)")
    servo_fixed_gain: Optional[float] = Field(
        default=None, gt=0,
        description="servo = 'fixed_gain': plate speed per unit relative stress error, |v| <= servo_max_velocity "
                    "[m/s]; default servo_max_velocity (YADE script: normalVEL)")
    servo_max_velocity: float = Field(default=0.05, gt=0, description="largest servo plate speed [m/s]")
    max_consolidation_steps: int = Field(default=100000, gt=0, description="safety cap on consolidation steps [-]")
    side_wall_material: str = Field(
        default="side_wall",
        description="material name of the box side walls (thesis: frictionless)")
    rows: int = Field(default=300, ge=10, le=100000, description="number of CSV rows over the shear distance [-]")
    band_thickness: float = Field(
        default=0.0, ge=0,
        description="thickness of the slab at the split plane for the Love-Weber check [m]; 0 = 2 d50")
    band_pictures: Optional[list[float]] = Field(
        default=None, min_length=1, max_length=50,
        description="shear displacements at which the shear band is drawn (shear_band_<delta>mm.png: the section "
                    "y = L/2 painted in 10 stripes along x, and coloured by u_x/delta) and its thickness measured "
                    "[m]; default: shear_distance / 3 and shear_distance")


class TriaxialSection(LabTestSection):
    size: float = Field(gt=0, description="side L of the cubical specimen (height = L) [m]")
    cell_pressure: float = Field(
        default=100e3, gt=0, le=10e6,
        description="confining stress sigma_3 held on the lateral walls (and on the top while consolidating) [Pa]")
    axial_strain: float = Field(
        default=0.25, gt=0, le=0.5,
        description="axial strain eps_1 = (H0 - H)/H0 at the end of the compression [-]")
    strain_rate: Optional[float] = Field(
        default=None, gt=0,
        description="axial strain rate [1/s]; default from inertial_number")
    ramp_strain: float = Field(
        default=0.005, ge=0,
        description="the axial velocity ramps up linearly (from 2 %) over this axial strain, so the lateral "
                    "servo follows the first load [-]")
    servo_max_velocity: Optional[float] = Field(
        default=None, gt=0,
        description="largest servo wall speed [m/s]; default twice the axial wall's (strain rate x size), so a "
                    "dilating specimen never outruns the lateral walls")
    max_consolidation_steps: int = Field(default=200000, gt=0, description="safety cap on consolidation steps [-]")
    wall_material: str = Field(
        default="side_wall", description="material name of the six walls (frictionless, as a lubricated cell)")
    rows: int = Field(default=200, ge=10, le=100000, description="number of CSV rows over the axial strain [-]")


# --------------------------------------------------------------------------- fe
class FeMaterial(Section):
    E: float = Field(gt=0, description="Young's modulus [Pa]")
    nu: float = Field(
        ge=0, lt=0.5,
        description="Poisson's ratio [-] (mixed u-p default alpha_tau is stable up to 0.499)")
    rho: float = Field(gt=0, description="density [kg/m^3]")
    group: Optional[str] = Field(
        default=None,
        description="cell physical-group name this material fills; omit for the whole mesh")


class FeBoundaryCondition(Section):
    type: Literal["fixed", "velocity"] = Field(
        description="'fixed' (zero displacement) or 'velocity' (prescribed velocity)")
    boundary: str = Field(min_length=1, description="facet physical-group name in the mesh")
    components: list[Annotated[int, Field(ge=0, le=2)]] = Field(
        default=[0, 1, 2], min_length=1, max_length=3,
        description="constrained components, 0=x 1=y 2=z")
    velocity: Optional[Vec3] = Field(default=None, description="prescribed velocity for type='velocity' [m/s]")
    ramp: Optional[float] = Field(
        default=None, gt=0,
        description="time over which the velocity rises linearly from 0 [s]")


class FeLoad(Section):
    type: Literal["traction", "pressure", "body_force"] = Field(
        description="'traction' (vector), 'pressure' (normal, compressive > 0) on a boundary, or 'body_force'")
    boundary: Optional[str] = Field(default=None, description="facet physical-group name (traction, pressure)")
    traction: Optional[Vec3] = Field(default=None, description="traction vector for type='traction' [Pa]")
    pressure: Optional[float] = Field(default=None, description="normal pressure for type='pressure' [Pa]")
    acceleration: Optional[Vec3] = Field(default=None, description="body acceleration for type='body_force' [m/s^2]")
    ramp: Optional[float] = Field(default=None, gt=0, description="time over which the load rises linearly from 0 [s]")


class FeDamping(Section):
    type: Literal["local", "mass"] = Field(
        description="'local' non-viscous (alpha in [0,1)) or 'mass'-proportional (alpha in 1/s)")
    alpha: float = Field(ge=0, description="damping coefficient: local [-] or mass-proportional [1/s]")


class FeSection(Section):
    mesh: str = Field(
        min_length=1,
        description="gmsh .geo source or .msh file, relative to the case file or a name in meshes/")
    mesh_size: Optional[float] = Field(default=None, gt=0, description="target element size for a .geo source [m]")
    geometry_parameters: dict[str, float] = Field(
        default_factory=dict,
        description="overrides of the .geo DefineConstant values [m]")
    formulation: Literal["mixed", "displacement"] = Field(
        default="mixed",
        description="'mixed' u-p with OSS stabilisation, or pure-displacement P1")
    alpha_tau: Optional[float] = Field(
        default=None, gt=0,
        description="stabilisation factor in tau_e = alpha_tau h_e^2/(2G) [-]; default: "
                    "half the measured stability bound 0.6 G/K of the most incompressible material")
    materials: list[FeMaterial] = Field(min_length=1, description="[[fe.materials]] tables")
    boundary_conditions: list[FeBoundaryCondition] = Field(
        default_factory=list,
        description="[[fe.boundary_conditions]] tables")
    loads: list[FeLoad] = Field(default_factory=list, description="[[fe.loads]] tables")
    damping: Optional[FeDamping] = Field(default=None, description="[fe.damping] for quasi-static runs")
    reactions: list[str] = Field(
        default_factory=list,
        description="facet groups whose reaction force is written to the series CSV")


class CouplingSection(Section):
    interface: list[str] = Field(
        min_length=1,
        description="facet physical groups of the FE mesh that the particles touch (a name or a list)")

    @field_validator("interface", mode="before")
    @classmethod
    def _one_name_is_a_list(cls, value):
        return [value] if isinstance(value, str) else value
    material: str = Field(min_length=1, description="DEM material name of the interface facets")
    subcycles: Optional[int] = Field(
        default=None, ge=1,
        description="DEM steps per FE step [-]; default the largest the FE stability allows")
    smoothing_time: float = Field(
        default=0.0, ge=0,
        description="time constant tau of an optional low-pass filter on the interface force: each FE step "
                    "the FE gets 1 - exp(-dt_FE/tau) of the impulse collected and not yet applied, the rest "
                    "stays in transit (momentum exactly conserved); 0: off, the whole window's impulse [s]")
    fe_partition: Literal["replicated", "distributed"] = Field(
        default="replicated",
        description="under mpirun: 'replicated', every rank steps the whole FE mesh (no FE messages; the run "
                    "bit-identical to one rank's); 'distributed', the FE mesh partitioned over the ranks "
                    "(for FE meshes whose step costs more than a DEM step's share)")


# --------------------------------------------------------------------------- footing (docs/design.md §7)
class FootingSection(Section):
    model: Literal["coupled", "dem"] = Field(
        default="coupled",
        description="'coupled': grains in the zone only, an FE soil block around them; 'dem': the all-DEM "
                    "reference, the whole soil block made of the same grains between rigid walls")
    width: float = Field(gt=0, description="footing width B along x (it spans the slice along y) [m]")
    velocity: float = Field(default=0.05, gt=0, description="downward speed of the rigid footing [m/s]")
    settlement: float = Field(
        default=0.1, gt=0, le=0.5,
        description="the run ends at this settlement, as a fraction of B [-]")
    rows: int = Field(default=100, ge=10, le=100000, description="CSV rows over the settlement [-]")
    seating_pressure: float = Field(
        default=0.0, ge=0,
        description="seating load: the footing moves down from the highest grain under it until it carries this "
                    "bearing pressure, and the settlement is counted from there, in both models (as a plate load "
                    "test zeroes its gauge under a seating load); 0: from the first contact [Pa]")
    material: str = Field(default="plate", description="material name of the footing ([[dem.materials]])")
    sand_material: str = Field(default="sand", description="material name of the grains")
    side_wall_material: str = Field(
        default="side_wall",
        description="material of the frictionless walls: the y walls of the slice, the x walls of the all-DEM "
                    "block (the FE block's rollers), the generation box's sides")
    rest_unbalanced_force: float = Field(
        default=1e-3, gt=0, le=0.1,
        description="the model is at rest under gravity (before loading) when the unbalanced force ratio is "
                    "below this [-]")
    max_rest_time: float = Field(default=0.5, gt=0, description="safety cap on the simulated rest phase [s]")


class SoilSection(Section):
    width: float = Field(gt=0, description="soil block width W along x (all-DEM: the box) [m]")
    depth: float = Field(gt=0, description="soil block depth H along z [m]")
    thickness: float = Field(gt=0, description="slice thickness L_y along y, walls or rollers on both faces [m]")
    E: float = Field(gt=0, description="Young's modulus of the FE soil (e.g. from `cosim elastic`) [Pa]")
    nu: float = Field(ge=0, lt=0.5, description="Poisson's ratio of the FE soil [-]")
    rho: Optional[float] = Field(
        default=None, gt=0,
        description="density of the FE soil [kg/m^3]; default the bulk density of the zone's packing")
    K0: Optional[float] = Field(
        default=None, gt=0, le=3,
        description="coefficient of earth pressure at rest of the FE soil's initial stress (as "
                    "embedded.volumes[].K0); unset: K0 = nu / (1 - nu) from its settlement under its weight [-]")
    mesh_size: float = Field(gt=0, description="largest FE element size, far from the zone [m]")
    interface_mesh_size: float = Field(gt=0, description="FE element size at the zone's faces [m]")
    refinement_distance: Optional[float] = Field(
        default=None, gt=0,
        description="distance from the zone over which the element size grows to mesh_size [m]; default the "
                    "zone depth")
    damping: float = Field(
        default=0.5, ge=0, lt=1,
        description="local non-viscous damping of the FE soil (quasi-static, as the grains' [dem] one) [-]")
    fe_partition: Literal["replicated", "distributed"] = Field(
        default="replicated",
        description="under mpirun, as coupling.fe_partition: 'replicated', every rank steps the whole FE soil "
                    "(the run bit-identical to one rank's); 'distributed', the FE soil partitioned over the ranks")


class ZoneSection(Section):
    width: float = Field(gt=0, description="width w of the DEM zone (trench cavity) along x, centred [m]")
    depth: float = Field(gt=0, description="depth d of the DEM zone below the soil surface [m]")
    interface_material: str = Field(
        default="sand",
        description="material of the zone's faces as the grains see them (coupled: the FE interface; all-DEM: "
                    "the block's bottom)")
    subcycles: Optional[int] = Field(
        default=None, ge=1,
        description="DEM steps per FE step [-]; default the largest the FE stability allows")


# --------------------------------------------------------------------------- embedded (your own geometry)
class EmbeddedVolume(Section):
    group: str = Field(description="a physical volume of the model")
    role: Literal["soil", "zone", "structure"] = Field(
        description="'soil': FE soil in the coupled model, grains in the all-DEM twin; 'zone': grains in both; "
                    "'structure': FE in both (a lining, a pile, a wall)")
    E: Optional[float] = Field(default=None, gt=0, description="Young's modulus (soil, structure) [Pa]")
    nu: Optional[float] = Field(default=None, ge=0, lt=0.5, description="Poisson's ratio (soil, structure) [-]")
    rho: Optional[float] = Field(
        default=None, gt=0,
        description="density [kg/m^3]; a structure needs it; soil: default the bulk density of the zone's packing")
    inertia_scale: float = Field(
        default=1.0, ge=1, le=1e6,
        description="structure: mass scaling S, its inertia S x rho but its weight rho; raises its critical time step "
                    "by sqrt(S) so that a stiff lining or wall does not force the FE and DEM steps down (quasi-static "
                    "loading only: its natural periods grow by sqrt(S)) [-]")
    K0: Optional[float] = Field(
        default=None, gt=0, le=3,
        description="soil: the coefficient of earth pressure at rest of its initial (geostatic) stress, "
                    "sigma_h = K0 sigma_v below level ground at the model's top, so the FE soil starts at rest; "
                    "unset: it settles under its weight from zero stress, to K0 = nu / (1 - nu) between rollers [-]")


class EmbeddedSurface(Section):
    group: str = Field(description="a physical surface of the model")
    fe: Literal["free", "fixed", "roller"] = Field(
        default="free",
        description="on its FE faces: 'free', 'fixed' (u = 0), 'roller' (the normal displacement 0; the surface "
                    "must be a plane normal to x, y or z)")
    dem: Literal["free", "wall"] = Field(
        default="free",
        description="on the zone's faces that lie on it: 'free' (a free surface: the lid of the fill is removed) "
                    "or 'wall' (a fixed wall of `material`)")
    material: Optional[str] = Field(default=None, description="material of the DEM wall ([[dem.materials]])")


class RigidBody(Section):
    name: str = Field(pattern=r"^[A-Za-z][A-Za-z0-9_]{0,39}$",
                      description="name of the body (CSV columns <name>_force_x, ...)")
    surface: str = Field(description="the physical surface it is made of (its triangles are the body's facets)")
    material: str = Field(description="material of its faces ([[dem.materials]])")
    velocity: Vec3 = Field(default_factory=lambda: [0.0, 0.0, 0.0],
                           description="translation velocity during the loading [m/s]")
    angular_velocity: Vec3 = Field(default_factory=lambda: [0.0, 0.0, 0.0],
                                   description="rotation rate about `pivot` during the loading [rad/s]")
    pivot: Vec3 = Field(default_factory=lambda: [0.0, 0.0, 0.0],
                        description="the point it rotates about and moments are taken about [m]")
    seating_pressure: Optional[float] = Field(
        default=None, ge=0,
        description="place the body on the grains: it stands clear of them while they are filled in and come to "
                    "rest, then moves along its velocity to the first grain and on until it carries this pressure "
                    "(its force against the motion over its area), and the loading counts from there, as a plate "
                    "load test zeroes its gauge under a seating load; unset: the body is where the model puts it "
                    "and holds the grains while they are filled in [Pa]")


class EmbeddedLining(Section):
    volume: str = Field(description="a 'structure' volume that is a tunnel lining: a ring (or the part of one a "
                                    "model of symmetry holds) about the line through `centre` along `axis`")
    centre: Vec3 = Field(description="a point of the tunnel's axis [m]")
    axis: Vec3 = Field(default_factory=lambda: [0.0, 1.0, 0.0], description="the tunnel's axis [-]")
    volume_loss: float = Field(
        default=0.0, ge=0, lt=0.2,
        description="V_L: over the loading the lining contracts in its section by c = V_L / 2, ramped from 0 (a free "
                    "ring's area would shrink by V_L; the ground holds it back, so the ground's loss is less) [-]")


class EmbeddedSection(Section):
    model: Literal["coupled", "dem", "fe"] = Field(
        default="coupled",
        description="'coupled': grains in the 'zone' volumes, FE in the 'soil' and 'structure' ones; 'dem': the "
                    "all-DEM twin, every 'soil' volume filled with grains too; 'fe': the FE-only twin, every volume "
                    "linear elastic (a zone takes the first 'soil' volume's E, nu, K0 and density), solved "
                    "statically at rest and at each row of the loading")
    mesh: str = Field(description="the gmsh model (.geo or .msh), relative to the case file or in meshes/")
    mesh_size: Optional[float] = Field(default=None, gt=0, description="largest element size for a .geo [m]")
    parameters: dict[str, float] = Field(
        default_factory=dict, description="DefineConstant values of the .geo, e.g. {H = 0.06} [as the .geo]")
    volumes: list[EmbeddedVolume] = Field(min_length=1, description="[[embedded.volumes]]: a role per volume")
    surfaces: list[EmbeddedSurface] = Field(
        default_factory=list, description="[[embedded.surfaces]]: supports of the FE and walls of the DEM")
    rigid: list[RigidBody] = Field(default_factory=list, description="[[embedded.rigid]]: rigid bodies that move")
    ground: Optional[str] = Field(
        default=None,
        description="a surface group of the model that is the ground surface: its settlement during the loading "
                    "(its FE nodes, and the grains of the zone's top layer under it) in settlement_trough.csv")
    linings: list[EmbeddedLining] = Field(
        default_factory=list,
        description="[[embedded.linings]]: structure volumes that are tunnel linings: their thrust and bending moment "
                    "around the ring in series.csv and <volume>_sections.csv, and their contraction (volume loss)")
    loading_time: float = Field(gt=0, description="duration of the loading (the rigid bodies' motion) [s]")
    rows: int = Field(default=50, ge=5, le=100000, description="CSV rows over the loading [-]")
    sand_material: str = Field(default="sand", description="material name of the grains")
    interface_material: str = Field(
        default="sand", description="material of the FE interface as the grains see it ([[dem.materials]])")
    lid_material: str = Field(
        default="sand", description="material of the lid over a free surface while the zone is filled")
    rest_unbalanced_force: float = Field(
        default=1e-3, gt=0, le=0.1,
        description="the model is at rest under gravity (before loading) when the unbalanced force ratio is "
                    "below this [-]")
    max_rest_time: float = Field(default=0.5, gt=0, description="safety cap on the simulated rest phase [s]")
    damping: float = Field(default=0.5, ge=0, lt=1, description="local non-viscous damping of the FE volumes [-]")
    formulation: Literal["mixed", "displacement"] = Field(
        default="mixed",
        description="of the FE volumes: 'mixed' (u-p, free of volumetric locking as nu -> 0.5) or 'displacement' "
                    "(P1); take 'displacement' with a lining or another structure much stiffer than the soil: the "
                    "mixed form's pressure is continuous across their faces, smears the jump of the mean stress there "
                    "and bends a lining (docs/validation.md, the lining against Einstein & Schwartz)")
    subcycles: Optional[int] = Field(
        default=None, ge=1, description="DEM steps per FE step [-]; default the largest the FE stability allows")
    fe_partition: Literal["replicated", "distributed"] = Field(
        default="replicated", description="under mpirun, as coupling.fe_partition")


class Case(Section):
    case: CaseInfo
    time: TimeSection
    output: OutputSection = Field(default_factory=OutputSection)
    dem: Optional[DemSection] = None
    specimen: Optional[SpecimenSection] = None
    direct_shear: Optional[DirectShearSection] = None
    triaxial: Optional[TriaxialSection] = None
    fe: Optional[FeSection] = None
    coupling: Optional[CouplingSection] = None
    footing: Optional[FootingSection] = None
    soil: Optional[SoilSection] = None
    zone: Optional[ZoneSection] = None
    embedded: Optional[EmbeddedSection] = None


#: the sections each kind of case reads; a case giving another is refused
SECTIONS_OF_KIND = {
    "dem": ("case", "time", "output", "dem"),
    "direct_shear": ("case", "time", "output", "dem", "specimen", "direct_shear"),
    "triaxial": ("case", "time", "output", "dem", "specimen", "triaxial"),
    "fe": ("case", "time", "output", "fe"),
    "coupled": ("case", "time", "output", "dem", "fe", "coupling"),
    "footing": ("case", "time", "output", "dem", "specimen", "footing", "soil", "zone"),
    "embedded": ("case", "time", "output", "dem", "specimen", "embedded"),
}
