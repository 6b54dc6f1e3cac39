"""Case files: the typed TOML schema, ``--set`` overrides and validation.

One TOML file describes one complete run. Every field below has a type, a unit
(in its description) and an allowed range; unknown keys are errors. Validation
happens in three passes, all before any computation:

1. TOML syntax;
2. types, ranges and unknown keys (pydantic models, ``extra="forbid"``);
3. cross-field consistency and referenced files (``_check_consistency``).

Each failure raises :class:`cosim.errors.CaseError` naming the file, the dotted
key, the offending value and what is allowed. ``cosim schema`` prints the whole
schema with units.
"""
from __future__ import annotations

import copy
import re
import sys
import tomllib
from pathlib import Path
from typing import Annotated, Literal, Optional

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from cosim.errors import CaseError

Vec3 = Annotated[list[float], Field(min_length=3, max_length=3)]


class _Section(BaseModel):
    # strict: TOML has types, so "yes" is not a bool and "3" not a number; no NaN or inf
    # anywhere (a float key accepts an integer, as TOML users write 1 for 1.0)
    model_config = ConfigDict(extra="forbid", validate_assignment=True, strict=True, allow_inf_nan=False)


# --------------------------------------------------------------------------- case
class CaseInfo(_Section):
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


class TimeSection(_Section):
    duration: Optional[float] = Field(default=None, gt=0, description="simulated time [s] (give duration or steps)")
    steps: Optional[int] = Field(default=None, gt=0, description="number of time steps [-] (give duration or steps)")
    dt: Optional[float] = Field(default=None, gt=0, description="time step [s]; default safety_factor x critical step")
    safety_factor: float = Field(default=0.3, gt=0, le=0.5, description="fraction of the critical time step [-]")


class OutputSection(_Section):
    interval: float = Field(
        default=0.0, ge=0,
        description="time between CSV rows and VTK frames [s]; 0 = 20 frames per run")
    vtk: bool = Field(default=True, description="write particles/walls as VTU + PVD for ParaView")
    checkpoint_interval: float = Field(default=600.0, gt=0, description="wall-clock time between checkpoints [s]")
    progress_interval: float = Field(default=2.0, gt=0, description="wall-clock time between progress lines [s]")


# --------------------------------------------------------------------------- dem
class DemMaterial(_Section):
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


class DemParticles(_Section):
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


class DemWall(_Section):
    type: Literal["plane", "facets"] = Field(description="'plane': infinite plane; 'facets': triangle mesh file")
    point: Optional[Vec3] = Field(default=None, description="a point on the plane [m]")
    normal: Optional[Vec3] = Field(default=None, description="plane normal, pointing into the particles [-]")
    file: Optional[str] = Field(
        default=None,
        description="triangle mesh (.stl or gmsh .msh) for type='facets', relative to the case file")
    velocity: Vec3 = Field(default=[0.0, 0.0, 0.0], description="prescribed translation velocity [m/s]")
    material: str = Field(description="material name of the wall")


class DemSection(_Section):
    contact_law: Literal["linear", "hertz"] = Field(
        default="linear",
        description="'linear' (Cundall-Strack) or 'hertz' (Hertz-Mindlin)")
    gravity: Vec3 = Field(default=[0.0, 0.0, -9.81], description="gravitational acceleration [m/s^2]")
    local_damping: float = Field(default=0.0, ge=0, lt=1, description="non-viscous background damping alpha_b [-]")
    viscous_damping: float = Field(default=0.0, ge=0, description="viscous background damping alpha_v [1/s]")
    materials: list[DemMaterial] = Field(min_length=1, description="[[dem.materials]] tables")
    particles: Optional[DemParticles] = Field(default=None, description="[dem.particles]: the spheres of a 'dem' case")
    walls: list[DemWall] = Field(default_factory=list, description="[[dem.walls]] tables")


# --------------------------------------------------------------------------- direct shear (docs/design.md §3)
class SpecimenSection(_Section):
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


class DirectShearSection(_Section):
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
    inertial_number: float = Field(
        default=1e-3, gt=0, le=0.1,
        description="target I = (v/h) d50 sqrt(rho/sigma_n) when shear_velocity is not given [-]")
    ramp_distance: float = Field(
        default=2e-4, ge=0,
        description="the shear velocity ramps up linearly over this displacement [m]")
    servo: Literal["stiffness", "fixed_gain"] = Field(
        default="stiffness",
        description="servo law of the top plate: 'stiffness' (removes servo_gain of the stress error per update, "
                    "scaled by the plate's contact stiffness, PFC-style, with integral action) or 'fixed_gain' "
                    "(v = servo_fixed_gain x the relative stress error, as the thesis's YADE script)")
    servo_gain: float = Field(
        default=0.3, gt=0, le=1,
        description="fraction of the stress error the servo removes per update (PFC-style gain) [-]")
    servo_fixed_gain: Optional[float] = Field(
        default=None, gt=0,
        description="servo = 'fixed_gain': plate speed per unit relative stress error, |v| <= servo_max_velocity "
                    "[m/s]; default servo_max_velocity (YADE script: normalVEL)")
    servo_integral: float = Field(
        default=0.01, ge=0, le=0.2,
        description="integral action: per update the integral velocity grows by this x the proportional one [-]")
    servo_interval: int = Field(
        default=2, ge=1, le=1000,
        description="DEM steps between servo updates; the plate velocity is held in "
                    "between and the servo law uses this x dt [-]")
    servo_max_velocity: float = Field(default=0.05, gt=0, description="largest servo plate speed [m/s]")
    consolidation_tolerance: float = Field(
        default=0.01, gt=0, le=0.1,
        description="consolidation ends when |sigma - sigma_n|/sigma_n is below this ... [-]")
    consolidation_unbalanced_force: float = Field(
        default=0.02, gt=0, le=0.5,
        description="... and the unbalanced force ratio is below this [-]")
    max_consolidation_steps: int = Field(default=100000, gt=0, description="safety cap on consolidation steps [-]")
    sand_material: str = Field(default="sand", description="material name of the grains ([[dem.materials]])")
    side_wall_material: str = Field(
        default="side_wall",
        description="material name of the box side walls (thesis: frictionless)")
    plate_material: str = Field(default="plate", description="material name of the top and bottom plates (rough)")
    rows: int = Field(default=300, ge=10, le=100000, description="number of CSV rows over the shear distance [-]")
    residual_fraction: float = Field(
        default=0.2, gt=0, lt=1,
        description="residual = mean over the last fraction of the shear distance [-]")
    band_thickness: float = Field(
        default=0.0, ge=0,
        description="thickness of the slab at the split plane for the Love-Weber check [m]; 0 = 2 d50")
    band_pictures: Optional[list[float]] = Field(
        default=None, min_length=1, max_length=50,
        description="shear displacements at which the shear band is drawn (shear_band_<delta>mm.png: the section "
                    "y = L/2 painted in 10 stripes along x, and coloured by u_x/delta) and its thickness measured "
                    "[m]; default: shear_distance / 3 and shear_distance")


# --------------------------------------------------------------------------- fe
class FeMaterial(_Section):
    E: float = Field(gt=0, description="Young's modulus [Pa]")
    nu: float = Field(
        ge=0, lt=0.5,
        description="Poisson's ratio [-] (mixed u-p default alpha_tau is stable up to 0.499)")
    rho: float = Field(gt=0, description="density [kg/m^3]")
    group: Optional[str] = Field(
        default=None,
        description="cell physical-group name this material fills; omit for the whole mesh")


class FeBoundaryCondition(_Section):
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


class FeLoad(_Section):
    type: Literal["traction", "pressure", "body_force"] = Field(
        description="'traction' (vector), 'pressure' (normal, compressive > 0) on a boundary, or 'body_force'")
    boundary: Optional[str] = Field(default=None, description="facet physical-group name (traction, pressure)")
    traction: Optional[Vec3] = Field(default=None, description="traction vector for type='traction' [Pa]")
    pressure: Optional[float] = Field(default=None, description="normal pressure for type='pressure' [Pa]")
    acceleration: Optional[Vec3] = Field(default=None, description="body acceleration for type='body_force' [m/s^2]")
    ramp: Optional[float] = Field(default=None, gt=0, description="time over which the load rises linearly from 0 [s]")


class FeDamping(_Section):
    type: Literal["local", "mass"] = Field(
        description="'local' non-viscous (alpha in [0,1)) or 'mass'-proportional (alpha in 1/s)")
    alpha: float = Field(ge=0, description="damping coefficient: local [-] or mass-proportional [1/s]")


class FeSection(_Section):
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


class CouplingSection(_Section):
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
class FootingSection(_Section):
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


class SoilSection(_Section):
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


class ZoneSection(_Section):
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
class EmbeddedVolume(_Section):
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


class EmbeddedSurface(_Section):
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


class RigidBody(_Section):
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


class EmbeddedLining(_Section):
    volume: str = Field(description="a 'structure' volume that is a tunnel lining: a ring (or the part of one a "
                                    "model of symmetry holds) about the line through `centre` along `axis`")
    centre: Vec3 = Field(description="a point of the tunnel's axis [m]")
    axis: Vec3 = Field(default_factory=lambda: [0.0, 1.0, 0.0], description="the tunnel's axis [-]")
    volume_loss: float = Field(
        default=0.0, ge=0, lt=0.2,
        description="V_L: over the loading the lining contracts in its section by c = V_L / 2, ramped from 0 (a free "
                    "ring's area would shrink by V_L; the ground holds it back, so the ground's loss is less) [-]")


class EmbeddedSection(_Section):
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


class TriaxialSection(_Section):
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
    inertial_number: float = Field(
        default=1e-3, gt=0, le=0.1,
        description="target I = strain_rate d50 sqrt(rho/sigma_3) when strain_rate is not given [-]")
    ramp_strain: float = Field(
        default=0.005, ge=0,
        description="the axial velocity ramps up linearly (from 2 %) over this axial strain, so the lateral "
                    "servo follows the first load [-]")
    servo_gain: float = Field(
        default=0.3, gt=0, le=1,
        description="fraction of the stress error a servo wall removes per update (as direct_shear.servo_gain) [-]")
    servo_integral: float = Field(
        default=0.01, ge=0, le=0.2,
        description="integral action: per update the integral velocity grows by this x the proportional one [-]")
    servo_interval: int = Field(default=2, ge=1, le=1000, description="DEM steps between servo updates [-]")
    servo_max_velocity: Optional[float] = Field(
        default=None, gt=0,
        description="largest servo wall speed [m/s]; default twice the axial wall's (strain rate x size), so a "
                    "dilating specimen never outruns the lateral walls")
    consolidation_tolerance: float = Field(
        default=0.01, gt=0, le=0.1,
        description="consolidation ends when every |sigma - sigma_3|/sigma_3 is below this ... [-]")
    consolidation_unbalanced_force: float = Field(
        default=0.02, gt=0, le=0.5, description="... and the unbalanced force ratio is below this [-]")
    max_consolidation_steps: int = Field(default=200000, gt=0, description="safety cap on consolidation steps [-]")
    sand_material: str = Field(default="sand", description="material name of the grains ([[dem.materials]])")
    wall_material: str = Field(
        default="side_wall", description="material name of the six walls (frictionless, as a lubricated cell)")
    plate_material: str = Field(
        default="plate", description="material name of the generation box's bottom and compaction plate")
    rows: int = Field(default=200, ge=10, le=100000, description="number of CSV rows over the axial strain [-]")
    residual_fraction: float = Field(
        default=0.2, gt=0, lt=1,
        description="critical state = mean over the last fraction of the axial strain [-]")


class Case(_Section):
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


# --------------------------------------------------------------------------- loading
def load_case(path, overrides=()):
    """Read, override and validate a case file; return ``(Case, resolved dict)``.

    ``overrides`` are ``"section.key=value"`` strings; ``value`` is parsed as a
    TOML value (``1e-3``, ``true``, ``[0, 0, -9.81]``) or else taken as a string.
    Relative file paths in the case are resolved against the case file's folder.
    """
    path = Path(path)
    if not path.is_file():
        raise CaseError(path, "<file>", str(path), "the case file must exist and be a readable TOML file")
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
    except UnicodeDecodeError as exc:
        raise CaseError(path, "<encoding>", f"byte {exc.object[exc.start:exc.start + 1]!r} at offset {exc.start}",
                        "a case file must be UTF-8 text (TOML)") from None
    except tomllib.TOMLDecodeError as exc:
        raise CaseError(path, "<syntax>", str(exc), "the file must be valid TOML") from None
    raw = apply_overrides(path, raw, overrides)
    _check_sections(path, raw)
    try:
        case = Case.model_validate(raw)
    except ValidationError as exc:
        raise schema_error(path, exc) from None
    _check_consistency(path, case)
    return case, case.model_dump()


def apply_overrides(path, raw, overrides):
    """Return a copy of ``raw`` with ``--set a.b.c=value`` overrides applied."""
    raw = copy.deepcopy(raw)
    for item in overrides:
        if "=" not in item:
            raise CaseError(path, item, item, "--set needs the form section.key=value")
        key, text = item.split("=", 1)
        try:
            value = tomllib.loads(f"v = {text}")["v"]
        except tomllib.TOMLDecodeError:
            value = text
        parts = _override_path(path, key.strip(), text)
        node = raw
        for depth, part in enumerate(parts[:-1]):
            if isinstance(part, int):
                if not isinstance(node, list) or part >= len(node):
                    where = _dotted(parts[:depth])
                    count = len(node) if isinstance(node, list) else 0
                    raise CaseError(path, key, text, f"'{where}' has {count} entries in the case file; "
                                                     f"index {part} is not one of them")
                node = node[part]
                continue
            nxt = node.get(part)
            if nxt is None:
                nxt = node.setdefault(part, [] if isinstance(parts[depth + 1], int) else {})
            if not isinstance(nxt, (dict, list)):
                raise CaseError(path, key, text, f"'{_dotted(parts[:depth + 1])}' is a value, not a table")
            node = nxt
        if not isinstance(node, dict):
            raise CaseError(path, key, text, "--set names a key of a table: section.key or section.list[i].key")
        node[parts[-1]] = value
    return raw


def _override_path(path, key, text):
    """``dem.materials[0].friction`` → ["dem", "materials", 0, "friction"]."""
    parts = []
    for piece in key.split("."):
        match = re.fullmatch(r"([A-Za-z_][A-Za-z0-9_]*)((?:\[\d+\])*)", piece)
        if match is None:
            raise CaseError(path, key, text, "--set needs section.key=value (a list entry: section.list[i].key=value)")
        parts.append(match.group(1))
        parts.extend(int(i) for i in re.findall(r"\[(\d+)\]", match.group(2)))
    if isinstance(parts[-1], int):
        raise CaseError(path, key, text, "--set replaces one key, not a whole list entry")
    return parts


def _dotted(loc):
    out = ""
    for part in loc:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out


def schema_error(path, exc, root=None):
    """The first pydantic error of a file validated against ``root`` (default :class:`Case`)
    as a CaseError naming the dotted key, the value and what is allowed."""
    root = root or Case
    err = exc.errors()[0]
    loc = [p for p in err["loc"] if not (isinstance(p, str) and ("[" in p or p.startswith("function-")))]
    key = _dotted(loc)
    msg = err["msg"]
    if err["type"] == "extra_forbidden":
        parent = _model_at(loc[:-1], root)
        allowed = ", ".join(parent.model_fields) if parent else "see `cosim schema`"
        return CaseError(path, key, err.get("input"), f"unknown key; allowed keys here: {allowed}")
    if err["type"] == "missing":
        return CaseError(path, key, None, "required key is missing")
    field = _field_at(loc, root)
    desc = f" ({field.description})" if field is not None and field.description else ""
    return CaseError(path, key, err.get("input"), msg + desc)


def _model_at(loc, root):
    model = root
    for part in loc:
        if isinstance(part, int):
            continue
        field = model.model_fields.get(part)
        if field is None:
            return None
        model = _inner_model(field.annotation)
        if model is None:
            return None
    return model


def _field_at(loc, root):
    parent = _model_at(loc[:-1], root)
    names = [p for p in loc if isinstance(p, str)]
    if parent is None or not names:
        return None
    return parent.model_fields.get(names[-1])


def _inner_model(annotation):
    """The BaseModel inside Optional[...] / list[...], if any."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    for arg in getattr(annotation, "__args__", ()):
        inner = _inner_model(arg)
        if inner is not None:
            return inner
    return None


def warn(file, key, value, text):
    """A legal but suspicious value: one line on rank 0, the run goes on."""
    from cosim.outputs import say
    say(f"cosim: warning: {file}: key '{key}' = {value!r}: {text}", file=sys.stderr)


def resolve_path(case_file, relative):
    """A path in a case file, relative to the case file's folder."""
    p = Path(relative)
    return p if p.is_absolute() else (Path(case_file).parent / p).resolve()


SECTIONS_OF_KIND = {
    "dem": ("case", "time", "output", "dem"),
    "direct_shear": ("case", "time", "output", "dem", "specimen", "direct_shear"),
    "triaxial": ("case", "time", "output", "dem", "specimen", "triaxial"),
    "fe": ("case", "time", "output", "fe"),
    "coupled": ("case", "time", "output", "dem", "fe", "coupling"),
    "footing": ("case", "time", "output", "dem", "specimen", "footing", "soil", "zone"),
    "embedded": ("case", "time", "output", "dem", "specimen", "embedded"),
}

# keys a kind (or a choice inside a table) does not use: (table, keys, when, why).
# Given anyway, they are refused, never silently ignored.
_UNUSED = [
    ("time", ("dt",), lambda c, s: c.case.kind == "coupled",
     "a coupled run takes dt_FE = subcycles x dt_DEM within both stability limits; "
     "set time.safety_factor and coupling.subcycles instead"),
    ("time", ("dt",), lambda c, s: c.case.kind == "footing",
     "a footing run takes dt = time.safety_factor x the critical step (of the DEM and the FE, with "
     "zone.subcycles DEM steps per FE step), the same for both models"),
    ("time", ("dt",), lambda c, s: c.case.kind == "embedded",
     "an embedded run takes dt = time.safety_factor x the critical step of the DEM and the FE"),
    ("output", ("interval",), lambda c, s: c.case.kind == "embedded",
     "an embedded run writes embedded.rows CSV rows over the loading; set rows instead"),
    ("embedded", ("mesh_size", "parameters"), lambda c, s: s.mesh.endswith(".msh"), "a .msh file is already meshed"),
    ("embedded.volumes[]", ("E", "nu", "rho", "K0", "inertia_scale"), lambda c, s: s.role == "zone",
     "a zone is made of grains"),
    ("embedded.volumes[]", ("K0",), lambda c, s: s.role == "structure",
     "a structure is not in the ground's stress at rest; K0 is for 'soil' volumes"),
    ("embedded.volumes[]", ("inertia_scale",), lambda c, s: s.role == "soil",
     "mass scaling is for a stiff structure (a lining, a wall); the soil's inertia meets the grains' at the interface"),
    ("embedded.surfaces[]", ("material",), lambda c, s: s.dem == "free", "a free surface has no wall"),
    ("output", ("interval",), lambda c, s: c.case.kind == "footing",
     "a footing run writes footing.rows CSV rows over the settlement; set rows instead"),
    ("output", ("interval",), lambda c, s: c.case.kind == "direct_shear",
     "a direct_shear run writes direct_shear.rows CSV rows over the shear distance; set rows instead"),
    ("output", ("interval",), lambda c, s: c.case.kind == "triaxial",
     "a triaxial run writes triaxial.rows CSV rows over the axial strain; set rows instead"),
    ("output", ("vtk",), lambda c, s: c.case.kind == "fe",
     "an fe run always writes its fields as XDMF; vtk is for particles"),
    ("dem.particles", ("file",), lambda c, s: s.source == "cloud", "source = 'cloud' reads no file"),
    ("dem.particles", ("count", "box", "radius"), lambda c, s: s.source == "file",
     "source = 'file' takes the spheres from the file"),
    ("dem.walls[]", ("file",), lambda c, s: s.type == "plane", "a plane wall has no mesh file"),
    ("dem.walls[]", ("point", "normal"), lambda c, s: s.type == "facets", "a facets wall is given by its mesh file"),
    ("specimen", ("file",), lambda c, s: s.source == "generate", "source = 'generate' reads no file"),
    ("specimen", tuple(n for n in SpecimenSection.model_fields if n not in ("source", "file")),
     lambda c, s: s.source == "file", "source = 'file' takes the specimen as it is from the file"),
    ("specimen", ("layers", "undercompaction", "friction_reduction", "hold_friction"),
     lambda c, s: s.source == "generate" and s.method == "radius_expansion",
     "method = 'radius_expansion' grows the radii of one cloud in the closed box: no layers, no compaction plate"),
    ("direct_shear", ("servo_fixed_gain",), lambda c, s: s.servo == "stiffness",
     "servo = 'stiffness' scales its speed by the plate's contact stiffness; set servo_gain"),
    ("direct_shear", ("servo_gain", "servo_integral"), lambda c, s: s.servo == "fixed_gain",
     "servo = 'fixed_gain' is v = servo_fixed_gain x the relative stress error, without integral action"),
    ("direct_shear", ("sample_height",), lambda c, s: c.specimen is not None and c.specimen.source == "file",
     "with specimen.source = 'file' the height is the packing's (the stored plate height of a .npz "
     "written by this app, else the top of the highest grain)"),
    ("fe", ("mesh_size", "geometry_parameters"), lambda c, s: s.mesh.endswith(".msh"),
     "a .msh file is already meshed"),
    ("fe.boundary_conditions[]", ("velocity", "ramp"), lambda c, s: s.type == "fixed",
     "a fixed boundary has no velocity"),
    ("fe.loads[]", ("traction", "acceleration"), lambda c, s: s.type == "pressure", "type = 'pressure' reads pressure"),
    ("fe.loads[]", ("pressure", "acceleration"), lambda c, s: s.type == "traction", "type = 'traction' reads traction"),
    ("fe.loads[]", ("boundary", "traction", "pressure"), lambda c, s: s.type == "body_force",
     "type = 'body_force' acts on the whole body with its acceleration"),
]


def _tables(case, table):
    """(dotted key, model) of every table at ``table`` ("a.b", or "a.b[]" for each entry of a list)."""
    name, is_list = table.removesuffix("[]"), table.endswith("[]")
    node = case
    for part in name.split("."):
        node = getattr(node, part, None) if node is not None else None
    if node is None:
        return []
    return [(f"{name}[{i}]", entry) for i, entry in enumerate(node)] if is_list else [(name, node)]


def _check_sections(path, raw):
    """Refuse a section the case's kind does not use (before the sections' own checks)."""
    kind = raw.get("case", {}).get("kind") if isinstance(raw.get("case"), dict) else None
    if kind not in SECTIONS_OF_KIND:
        return  # the schema names the bad or missing kind
    for section in raw:
        if section not in SECTIONS_OF_KIND[kind] and section in Case.model_fields:
            raise CaseError(path, section, f"[{section}]", f"a case of kind '{kind}' does not use [{section}]; "
                                                           f"its sections: {', '.join(SECTIONS_OF_KIND[kind])}")


def _check_used(path, case):
    """Refuse keys the case's kind, or a choice in their table, does not use."""
    for table, keys, when, why in _UNUSED:
        for dotted, model in _tables(case, table):
            given = [k for k in keys if k in model.model_fields_set]
            if given and when(case, model):
                raise CaseError(path, f"{dotted}.{given[0]}", getattr(model, given[0]), f"not used here: {why}")


def _check_consistency(path, case):
    """Cross-field rules pydantic's per-field ranges cannot express."""
    t = case.time
    _check_used(path, case)
    if case.case.kind == "direct_shear":
        _check_direct_shear(path, case)
        return
    if case.case.kind == "footing":
        _check_footing(path, case)
        return
    if case.case.kind == "embedded":
        _check_embedded(path, case)
        return
    if case.case.kind == "triaxial":
        _check_triaxial(path, case)
        return
    if (t.duration is None) == (t.steps is None):
        raise CaseError(path, "time.duration / time.steps", (t.duration, t.steps),
                        "give exactly one of duration [s] or steps")
    if case.output.interval and t.duration and case.output.interval > t.duration:
        raise CaseError(path, "output.interval", case.output.interval,
                        f"must not exceed time.duration = {t.duration} s")
    if case.case.kind == "dem":
        if case.dem is None:
            raise CaseError(path, "dem", None, "a case of kind 'dem' needs a [dem] section")
        _check_dem(path, case.dem)
    if case.case.kind in ("fe", "coupled"):
        if case.fe is None:
            raise CaseError(path, "fe", None, f"a case of kind '{case.case.kind}' needs an [fe] section")
        _check_fe(path, case.fe)
    if case.case.kind == "coupled":
        _check_coupling(path, case)


def _check_coupling(path, case):
    for section in ("dem", "coupling"):
        if getattr(case, section) is None:
            raise CaseError(path, section, None, f"a case of kind 'coupled' needs a [{section}] section")
    _check_dem(path, case.dem)
    names = [m.name for m in case.dem.materials]
    if case.coupling.material not in names:
        raise CaseError(path, "coupling.material", case.coupling.material, f"must be one of the materials: {names}")
    mesh = mesh_path(path, case.fe.mesh)
    surfaces = sorted(n for n, d in physical_groups(mesh).items() if d == 2)
    for i, name in enumerate(case.coupling.interface):
        if name not in surfaces:
            raise CaseError(path, f"coupling.interface[{i}]", name,
                            f"not a surface physical group of {mesh.name}; available: {surfaces}")


def mesh_path(case_file, name):
    """A mesh named in a case: relative to the case file, else in the project's meshes/ folder."""
    local = resolve_path(case_file, name)
    if local.exists():
        return local
    return Path(__file__).resolve().parent.parent / "meshes" / name


def physical_groups(mesh_file):
    """``{name: dim}`` of the physical groups a .geo source or .msh file declares (text scan, no meshing)."""
    text = Path(mesh_file).read_text(errors="replace")
    if Path(mesh_file).suffix == ".geo":
        dims = {"Point": 0, "Curve": 1, "Line": 1, "Surface": 2, "Volume": 3}
        physical = r'Physical\s+(Point|Curve|Line|Surface|Volume)\s*\(\s*"([^"]+)"'
        return {m.group(2): dims[m.group(1)] for m in re.finditer(physical, text)}
    block = re.search(r"\$PhysicalNames\s*\n\s*\d+\s*\n(.*?)\$EndPhysicalNames", text, re.S)
    if block is None:
        return {}
    return {m.group(3): int(m.group(1)) for m in re.finditer(r'(\d+)\s+(\d+)\s+"([^"]+)"', block.group(1))}


_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"


def parameter_ranges(geo_file):
    """``{name: (min, max)}`` of the ``DefineConstant`` parameters of a .geo source: the range
    its ``Min`` and ``Max`` attributes declare (None where one is not declared)."""
    text = Path(geo_file).read_text(errors="replace")
    starts = [m.end() for m in re.finditer(r"\w+\s*=\s*\{", text)] + [len(text)]  # "name = {" of each entry
    ranges = {}
    for entry in re.finditer(r'Name\s+"Parameters/([^"]+)"', text):
        start = max((k for k in starts if k <= entry.start()), default=0)
        end = min((k for k in starts if k > entry.end()), default=len(text))
        attributes = text[start:end].split("]", 1)[0]  # to the next entry or the end of DefineConstant[...]
        bounds = [re.search(rf"\b{bound}\s+({_NUMBER})", attributes) for bound in ("Min", "Max")]
        ranges[entry.group(1)] = tuple(float(b.group(1)) if b else None for b in bounds)
    return ranges


def _check_geometry_parameter(path, mesh, name, value, bounds):
    """A .geo parameter the case sets: within the range its DefineConstant declares, and not
    negative where it declares no lower bound (the lengths and counts of a geometry)."""
    low, high = bounds
    key = f"fe.geometry_parameters.{name}"
    if low is None and value < 0:
        raise CaseError(path, key, value, f"must be >= 0: {mesh.name} declares no lower bound for {name} (a length "
                                          "or a count); a .geo parameter may be negative only where its "
                                          "DefineConstant declares a Min below zero")
    if (low is not None and value < low) or (high is not None and value > high):
        allowed = f"[{'-inf' if low is None else f'{low:g}'}, {'inf' if high is None else f'{high:g}'}]"
        raise CaseError(path, key, value, f"outside the range {allowed} {mesh.name} declares for {name}")


def _check_fe(path, fe):
    mesh = mesh_path(path, fe.mesh)
    if not mesh.is_file():
        raise CaseError(path, "fe.mesh", fe.mesh,
                        f"mesh not found (looked for {resolve_path(path, fe.mesh)} and {mesh})")
    if mesh.suffix not in (".geo", ".msh"):
        raise CaseError(path, "fe.mesh", fe.mesh, "allowed formats: gmsh .geo source or .msh mesh")
    if mesh.suffix == ".geo" and fe.mesh_size is None:
        raise CaseError(path, "fe.mesh_size", None, "a .geo source needs a mesh size > 0 [m]")
    if mesh.suffix == ".geo":
        known = parameter_ranges(mesh)
        for name, value in fe.geometry_parameters.items():
            if name not in known:
                raise CaseError(path, f"fe.geometry_parameters.{name}", value,
                                f"{mesh.name} defines no such parameter; its parameters: {sorted(known)}")
            _check_geometry_parameter(path, mesh, name, value, known[name])
    if mesh.suffix == ".msh" and not Path(mesh).read_bytes()[:200].lstrip().startswith(b"$MeshFormat"):
        raise CaseError(path, "fe.mesh", fe.mesh, f"{mesh.name} is not a gmsh .msh file (no $MeshFormat header)")
    groups = physical_groups(mesh)
    if not groups:
        raise CaseError(path, "fe.mesh", fe.mesh,
                        f"{mesh.name} names no physical groups; the case addresses materials, boundaries and loads "
                        "by group name (Physical Volume/Surface(\"name\") in gmsh)")
    surfaces = sorted(n for n, d in groups.items() if d == 2)
    volumes = sorted(n for n, d in groups.items() if d == 3)

    def check_surface(key, name):
        if name not in surfaces:
            raise CaseError(path, key, name, f"not a surface physical group of {mesh.name}; available: {surfaces}")

    whole = [i for i, m in enumerate(fe.materials) if m.group is None]
    if whole and len(fe.materials) > 1:
        raise CaseError(path, f"fe.materials[{whole[0]}].group", None,
                        "with several materials each needs its cell group")
    for i, m in enumerate(fe.materials):
        if m.group is not None and m.group not in volumes:
            raise CaseError(path, f"fe.materials[{i}].group", m.group,
                            f"not a volume physical group of {mesh.name}; available: {volumes}")
    for i, bc in enumerate(fe.boundary_conditions):
        check_surface(f"fe.boundary_conditions[{i}].boundary", bc.boundary)
        if bc.type == "velocity" and bc.velocity is None:
            raise CaseError(path, f"fe.boundary_conditions[{i}].velocity", None,
                            "type = 'velocity' needs velocity = [vx, vy, vz] [m/s]")
    needs = {"traction": "traction", "pressure": "pressure", "body_force": "acceleration"}
    for i, load in enumerate(fe.loads):
        if getattr(load, needs[load.type]) is None:
            raise CaseError(path, f"fe.loads[{i}].{needs[load.type]}", None,
                            f"type = '{load.type}' needs {needs[load.type]}")
        if load.type != "body_force":
            if load.boundary is None:
                raise CaseError(path, f"fe.loads[{i}].boundary", None, f"type = '{load.type}' needs a boundary")
            check_surface(f"fe.loads[{i}].boundary", load.boundary)
    for i, name in enumerate(fe.reactions):
        check_surface(f"fe.reactions[{i}]", name)
    if fe.alpha_tau is not None:
        from fe_domain.explicit import stable_alpha_tau
        nu_max = max(m.nu for m in fe.materials)
        bound = stable_alpha_tau(nu_max, margin=1.0)
        if fe.alpha_tau > bound:
            raise CaseError(path, "fe.alpha_tau", fe.alpha_tau,
                            f"step 3 is unstable above alpha_tau = {bound:.3g} for nu = {nu_max} (measured bound "
                            f"alpha_tau K/G <= C); omit the key for the default {stable_alpha_tau(nu_max):.3g}")
    if fe.damping is not None and fe.damping.type == "local" and fe.damping.alpha >= 1:
        raise CaseError(path, "fe.damping.alpha", fe.damping.alpha, "local non-viscous damping needs 0 <= alpha < 1")


def _check_packing_file(path, key, value):
    """A packing named by a case exists and has a format ``de_domain.packing`` reads."""
    if value is None:
        raise CaseError(path, key, None, "source = 'file' needs a packing file (.npz or .txt)")
    f = resolve_path(path, value)
    if not f.is_file():
        raise CaseError(path, key, value, f"file not found (looked for {f})")
    if f.suffix not in (".npz", ".txt", ".dat", ".dump"):
        raise CaseError(path, key, value,
                        "allowed formats: .npz, .txt/.dat ('x y z r'), .dump (LIGGGHTS 'id radius x y z')")
    if f.stat().st_size == 0:
        raise CaseError(path, key, value, f"the file {f} is empty (0 bytes); give a packing with spheres: .npz "
                                          "(arrays 'positions', 'radii'), .txt/.dat ('x y z r') or .dump")


def _check_dem(path, dem):
    names = [m.name for m in dem.materials]
    for i, name in enumerate(names):
        if name in names[:i]:
            raise CaseError(path, f"dem.materials[{i}].name", name, "material names must be unique")
    p = dem.particles
    if p is None:
        raise CaseError(path, "dem.particles", None, "a case of kind 'dem' needs a [dem.particles] table")
    if p.material not in names:
        raise CaseError(path, "dem.particles.material", p.material, f"must be one of the materials: {names}")
    if p.source == "file":
        _check_packing_file(path, "dem.particles.file", p.file)
    else:
        for key in ("count", "box", "radius"):
            if getattr(p, key) is None:
                raise CaseError(path, f"dem.particles.{key}", None, "source = 'cloud' needs count, box and radius")
        lo, hi = p.box
        if any(high <= low for low, high in zip(lo, hi, strict=True)):
            raise CaseError(path, "dem.particles.box", p.box, "each max corner coordinate must exceed the min corner")
        rmin, rmax = p.radius
        if not 0 < rmin <= rmax:
            raise CaseError(path, "dem.particles.radius", p.radius, "need 0 < r_min <= r_max [m]")
        if 2 * rmax >= min(high - low for low, high in zip(lo, hi, strict=True)):
            raise CaseError(path, "dem.particles.radius", p.radius, "the largest diameter must be smaller than the box")
    for i, w in enumerate(dem.walls):
        key = f"dem.walls[{i}]"
        if w.material not in names:
            raise CaseError(path, f"{key}.material", w.material, f"must be one of the materials: {names}")
        if w.type == "plane":
            if w.point is None or w.normal is None:
                raise CaseError(path, f"{key}.point/normal", (w.point, w.normal), "a plane wall needs point and normal")
            if sum(c * c for c in w.normal) == 0:
                raise CaseError(path, f"{key}.normal", w.normal, "the normal must be a non-zero vector")
        else:
            if w.file is None:
                raise CaseError(path, f"{key}.file", None, "a facets wall needs a mesh file (.stl or .msh)")
            f = resolve_path(path, w.file)
            if not f.is_file():
                raise CaseError(path, f"{key}.file", w.file, f"file not found (looked for {f})")


def _check_direct_shear(path, case):
    """A direct shear case: [dem] materials, [specimen], [direct_shear]; the run length
    follows from the shear distance, so [time] only sets dt / safety_factor."""
    t = case.time
    if t.duration is not None or t.steps is not None:
        raise CaseError(path, "time.duration / time.steps", (t.duration, t.steps),
                        "a direct_shear run lasts until direct_shear.shear_distance; "
                        "give only time.dt or time.safety_factor")
    for section in ("dem", "specimen", "direct_shear"):
        if getattr(case, section) is None:
            raise CaseError(path, section, None, f"a case of kind 'direct_shear' needs a [{section}] section")
    dem, sp, ds = case.dem, case.specimen, case.direct_shear
    if dem.particles is not None:
        raise CaseError(path, "dem.particles", "present",
                        "a direct_shear case builds its particles from [specimen]; remove [dem.particles]")
    if dem.walls:
        raise CaseError(path, "dem.walls", len(dem.walls),
                        "a direct_shear case builds the shear box itself; remove [[dem.walls]]")
    _check_materials(path, dem, [(f"direct_shear.{key}", getattr(ds, key))
                                 for key in ("sand_material", "side_wall_material", "plate_material")]
                     + _deposition_material(sp))
    if ds.shear_distance >= ds.box_length:
        raise CaseError(path, "direct_shear.shear_distance", ds.shear_distance,
                        f"must be smaller than box_length = {ds.box_length} m")
    if ds.ramp_distance >= ds.shear_distance:
        raise CaseError(path, "direct_shear.ramp_distance", ds.ramp_distance,
                        f"must be smaller than shear_distance = {ds.shear_distance} m")
    for delta in ds.band_pictures or ():
        if not 0.0 < delta <= ds.shear_distance:
            raise CaseError(path, "direct_shear.band_pictures", delta,
                            f"every shear displacement must lie in (0, shear_distance = {ds.shear_distance} m]")
    if sp.source == "file":
        _check_packing_file(path, "specimen.file", sp.file)
        return
    if ds.sample_height >= ds.box_length:
        raise CaseError(path, "direct_shear.sample_height", ds.sample_height,
                        f"must be smaller than box_length = {ds.box_length} m (ASTM D3080 asks for a box at least "
                        "twice as wide as the specimen is high)")
    if 2 * ds.sample_height > ds.box_length:
        warn(path, "direct_shear.sample_height", ds.sample_height,
             f"the box is less than twice as wide as the specimen is high (ASTM D3080: box_length >= 2 h = "
             f"{2 * ds.sample_height} m); the side walls will carry much of the load")
    d_max = _largest_grain(path, sp)
    if d_max >= 0.5 * ds.sample_height:
        raise CaseError(path, "specimen.truncate_above", sp.truncate_above,
                        f"the largest grain ({d_max * 1e3:.2f} mm after scaling) must be below half the sample height "
                        f"({0.5e3 * ds.sample_height:.2f} mm); set truncate_above or a smaller scale")


def _check_triaxial(path, case):
    """A triaxial case: [dem] materials, [specimen], [triaxial]; the run ends at the final
    axial strain, so [time] only sets dt / safety_factor."""
    t = case.time
    if t.duration is not None or t.steps is not None:
        raise CaseError(path, "time.duration / time.steps", (t.duration, t.steps),
                        "a triaxial run lasts until triaxial.axial_strain; give only time.dt or time.safety_factor")
    for section in ("dem", "specimen", "triaxial"):
        if getattr(case, section) is None:
            raise CaseError(path, section, None, f"a case of kind 'triaxial' needs a [{section}] section")
    dem, sp, tx = case.dem, case.specimen, case.triaxial
    if dem.particles is not None or dem.walls:
        raise CaseError(path, "dem.particles" if dem.particles is not None else "dem.walls", "present",
                        "a triaxial case builds its specimen from [specimen] and its walls itself; remove it")
    _check_materials(path, dem, [(f"triaxial.{key}", getattr(tx, key))
                                 for key in ("sand_material", "wall_material", "plate_material")]
                     + _deposition_material(sp))
    if sp.source == "file":
        _check_packing_file(path, "specimen.file", sp.file)
        return
    if tx.ramp_strain >= tx.axial_strain:
        raise CaseError(path, "triaxial.ramp_strain", tx.ramp_strain,
                        f"must be smaller than axial_strain = {tx.axial_strain}")
    d_max = _largest_grain(path, sp)
    if d_max > tx.size / 6:
        raise CaseError(path, "triaxial.size", tx.size,
                        f"must hold at least 6 of the largest grains ({d_max * 1e3:.2f} mm) across; "
                        f"give size >= {6 * d_max:.4g} m or smaller grains")


def _check_materials(path, dem, keys):
    """Unique material names, and every ``(dotted key, name)`` of ``keys`` one of them."""
    names = [m.name for m in dem.materials]
    for i, name in enumerate(names):
        if name in names[:i]:
            raise CaseError(path, f"dem.materials[{i}].name", name, "material names must be unique")
    for key, name in keys:
        if name not in names:
            raise CaseError(path, key, name, f"must be one of the materials: {names}")


def _deposition_material(sp):
    """The (key, name) of [specimen] deposition_material to check, if given."""
    return [] if sp.deposition_material is None else [("specimen.deposition_material", sp.deposition_material)]


def _largest_grain(path, sp):
    """d_max (m) of the sieve curve of a generated [specimen]; its errors as CaseErrors."""
    from de_domain.packing import SIEVE_PRESETS
    if (sp.sieve_diameters is None) != (sp.sieve_passing is None):
        raise CaseError(path, "specimen.sieve_diameters / sieve_passing", (sp.sieve_diameters, sp.sieve_passing),
                        "give both or neither")
    if sp.sieve_diameters is None and sp.sieve not in SIEVE_PRESETS:
        raise CaseError(path, "specimen.sieve", sp.sieve, f"allowed presets: {sorted(SIEVE_PRESETS)}")
    try:
        from de_domain.deposition import specimen_curve
        curve = specimen_curve(sp.sieve, sp.sieve_diameters, sp.sieve_passing, sp.scale,
                               sp.truncate_below, sp.truncate_above)
    except ValueError as exc:
        raise CaseError(path, "specimen", "sieve curve", str(exc)) from None
    return float(curve.diameters[-1])


GRAINS_ACROSS = 3  # a DEM zone or slice narrower than this many of the largest grains is refused


def _check_footing(path, case):
    """A footing case (docs/design.md §7): [dem] materials, [specimen], [footing], [soil], [zone];
    the run ends at the footing's final settlement, so [time] only sets safety_factor."""
    t = case.time
    if t.duration is not None or t.steps is not None:
        raise CaseError(path, "time.duration / time.steps", (t.duration, t.steps),
                        "a footing run lasts until footing.settlement; give only time.safety_factor")
    dem, sp, ft, soil, zone = case.dem, case.specimen, case.footing, case.soil, case.zone
    for section in ("dem", "specimen", "footing", "soil", "zone"):
        if getattr(case, section) is None:
            raise CaseError(path, section, None, f"a case of kind 'footing' needs a [{section}] section")
    if dem.particles is not None:
        raise CaseError(path, "dem.particles", "present",
                        "a footing case builds its grains from [specimen]; remove [dem.particles]")
    if dem.walls:
        raise CaseError(path, "dem.walls", len(dem.walls),
                        "a footing case builds its walls and footing itself; remove [[dem.walls]]")
    _check_materials(path, dem, [("footing.material", ft.material), ("footing.sand_material", ft.sand_material),
                                 ("footing.side_wall_material", ft.side_wall_material),
                                 ("zone.interface_material", zone.interface_material)]
                     + _deposition_material(case.specimen))
    if zone.width >= soil.width:
        raise CaseError(path, "zone.width", zone.width, f"must be smaller than soil.width = {soil.width} m "
                                                        "(the FE soil surrounds the zone)")
    if zone.depth >= soil.depth:
        raise CaseError(path, "zone.depth", zone.depth, f"must be smaller than soil.depth = {soil.depth} m "
                                                        "(the FE soil lies under the zone)")
    if ft.width >= zone.width:
        raise CaseError(path, "footing.width", ft.width, f"the footing must be narrower than the DEM zone "
                                                         f"(zone.width = {zone.width} m), which it loads")
    if soil.interface_mesh_size > soil.mesh_size:
        raise CaseError(path, "soil.interface_mesh_size", soil.interface_mesh_size,
                        f"must not exceed soil.mesh_size = {soil.mesh_size} m (the mesh is refined towards the zone)")
    if ft.settlement * ft.width >= zone.depth:
        raise CaseError(path, "footing.settlement", ft.settlement,
                        f"a settlement of {ft.settlement * ft.width} m reaches the zone's bottom "
                        f"(zone.depth = {zone.depth} m)")
    if sp.source == "file":
        _check_packing_file(path, "specimen.file", sp.file)
        return  # the packing is checked against the zone (or block) when read
    if sp.method != "radius_expansion":
        raise CaseError(path, "specimen.method", sp.method,
                        "a footing's grains are filled by 'radius_expansion' (grains grown inside the zone's faces, "
                        "the same sand in the zone and the all-DEM block; or give a packing: source = 'file')")
    d_max = _largest_grain(path, sp)
    for key, size in (("zone.width", zone.width), ("zone.depth", zone.depth), ("soil.thickness", soil.thickness)):
        if size < GRAINS_ACROSS * d_max * (1 - 1e-9):
            raise CaseError(path, key, size, f"the DEM zone must be at least {GRAINS_ACROSS} of the largest grains "
                                             f"({d_max * 1e3:.2f} mm after scaling) across: >= "
                                             f"{GRAINS_ACROSS * d_max:.4g} m; or set specimen.truncate_above")


def _check_embedded(path, case):
    """An embedded case: [dem] materials, [specimen] (radius expansion), [embedded] with one role
    per group; what needs the model itself (groups, dimensions, the zone's thickness) is
    checked when it is meshed (cosim.apps.embedded.prepare)."""
    t, dem, sp, em = case.time, case.dem, case.specimen, case.embedded
    for section in ("dem", "specimen", "embedded"):
        if getattr(case, section) is None:
            raise CaseError(path, section, None, f"a case of kind 'embedded' needs a [{section}] section")
    if t.duration is not None or t.steps is not None:
        raise CaseError(path, "time.duration / time.steps", (t.duration, t.steps),
                        "an embedded run lasts embedded.loading_time after the rest; give only time.safety_factor")
    if dem.particles is not None or dem.walls:
        raise CaseError(path, "dem.particles / dem.walls", "present",
                        "an embedded case takes its grains from [specimen] and its walls from the model; remove them")
    if sp.source == "file":
        _check_packing_file(path, "specimen.file", sp.file)  # its grains are checked against the model when read
    elif sp.method != "radius_expansion":
        raise CaseError(path, "specimen.method", sp.method,
                        "an embedded zone is filled by 'radius_expansion': grains grown inside the zone's faces "
                        "(or give a packing: source = 'file')")
    keys = [("embedded.sand_material", em.sand_material), ("embedded.interface_material", em.interface_material),
            ("embedded.lid_material", em.lid_material)]
    keys += [(f"embedded.surfaces[{i}].material", s.material) for i, s in enumerate(em.surfaces) if s.material]
    keys += [(f"embedded.rigid[{i}].material", r.material) for i, r in enumerate(em.rigid)]
    _check_materials(path, dem, keys + (_deposition_material(sp) if sp.source == "generate" else []))
    if sp.source == "generate":
        _largest_grain(path, sp)
    if not em.mesh.endswith((".geo", ".msh")):
        raise CaseError(path, "embedded.mesh", em.mesh, "a gmsh model: a .geo source or a .msh file")
    if em.mesh.endswith(".geo") and em.mesh_size is None:
        raise CaseError(path, "embedded.mesh_size", None, "a .geo model needs a mesh size [m]")
    seen = {}
    for key, group in ([(f"embedded.volumes[{i}].group", v.group) for i, v in enumerate(em.volumes)]
                       + [(f"embedded.surfaces[{i}].group", s.group) for i, s in enumerate(em.surfaces)]
                       + [(f"embedded.rigid[{i}].surface", r.surface) for i, r in enumerate(em.rigid)]):
        if group in seen:
            raise CaseError(path, key, group, f"this group already has a role ({seen[group]}): one role per group")
        seen[group] = key
    names = [r.name for r in em.rigid]
    for i, name in enumerate(names):
        if names.index(name) != i:
            raise CaseError(path, f"embedded.rigid[{i}].name", name, "two rigid bodies of one name")
        if em.rigid[i].seating_pressure is not None and not any(em.rigid[i].velocity):
            raise CaseError(path, f"embedded.rigid[{i}].seating_pressure", em.rigid[i].seating_pressure,
                            "a body placed on the grains is seated along its velocity: give it a velocity")
    for i, v in enumerate(em.volumes):
        needs = ("E", "nu", "rho") if v.role == "structure" else ("E", "nu") if v.role == "soil" else ()
        for key in needs:
            if getattr(v, key) is None:
                raise CaseError(path, f"embedded.volumes[{i}].{key}", None, f"a '{v.role}' volume needs {key}")
    if not any(v.role in ("zone", "soil") for v in em.volumes):
        raise CaseError(path, "embedded.volumes", [v.group for v in em.volumes],
                        "no volume holds grains: give at least one 'zone' (or, for the all-DEM twin, 'soil')")
    if em.model == "coupled" and not any(v.role == "zone" for v in em.volumes):
        raise CaseError(path, "embedded.volumes", [v.group for v in em.volumes],
                        "the coupled model needs a 'zone' volume (or set embedded.model = 'dem')")
    if em.model == "fe":
        _check_fe_only(path, em)
    for i, s in enumerate(em.surfaces):
        if s.dem == "wall" and s.material is None:
            raise CaseError(path, f"embedded.surfaces[{i}].material", None, "a DEM wall needs a material")
    structures = [v.group for v in em.volumes if v.role == "structure"]
    for i, lining in enumerate(em.linings):
        if lining.volume not in structures:
            raise CaseError(path, f"embedded.linings[{i}].volume", lining.volume,
                            f"a lining is a 'structure' volume of [[embedded.volumes]]: one of {structures}")
        if not any(lining.axis):
            raise CaseError(path, f"embedded.linings[{i}].axis", lining.axis, "the tunnel's axis must not be zero")


def _check_fe_only(path, em):
    """The FE-only twin (embedded.model = 'fe') is linear elastic and solved statically: the
    displacement formulation, the FE replicated on every rank, a 'soil' volume whose constants
    the zones take, no rigid bodies (they act on grains)."""
    if em.formulation != "displacement":
        raise CaseError(path, "embedded.formulation", em.formulation,
                        "the FE-only model (embedded.model = 'fe') is solved statically: 'displacement'")
    if em.fe_partition != "replicated":
        raise CaseError(path, "embedded.fe_partition", em.fe_partition,
                        "the FE-only model is solved on each rank's whole copy: 'replicated'")
    if em.rigid:
        raise CaseError(path, "embedded.rigid", [r.name for r in em.rigid],
                        "rigid bodies move grains: the FE-only model has none; remove them or run 'coupled'")
    if not any(v.role == "soil" for v in em.volumes):
        raise CaseError(path, "embedded.volumes", [v.group for v in em.volumes],
                        "the FE-only model gives the zones the first 'soil' volume's E, nu, K0 and density: "
                        "give a 'soil' volume")


# --------------------------------------------------------------------------- calibration files (cosim calibrate)
#: what a calibration target can be, read from a lab run's summary.json
CALIBRATION_QUANTITIES = {
    "peak_friction_angle_deg": "peak friction angle phi_peak [deg]",
    "residual_friction_angle_deg": "residual (triaxial: critical-state) friction angle [deg]",
    "vertical_displacement_end": "direct_shear: vertical displacement of the top plate at the end, dilation + [m]",
    "volumetric_strain_end": "triaxial: volumetric strain at the end, contraction + [-]",
    "void_ratio_change": "void ratio at the end minus after consolidation [-]",
}
#: the quantities only one lab kind measures
CALIBRATION_QUANTITY_KIND = {"vertical_displacement_end": "direct_shear", "volumetric_strain_end": "triaxial"}


class CalibrationTarget(_Section):
    quantity: Literal[tuple(CALIBRATION_QUANTITIES)] = Field(
        description="a lab test's result: " + "; ".join(f"{k}: {v}" for k, v in CALIBRATION_QUANTITIES.items()))
    value: float = Field(description="the value to reach (unit of the quantity)")
    tolerance: float = Field(gt=0, description="reached when |achieved - value| <= this (unit of the quantity)")
    normal_stress: float = Field(
        gt=0, le=10e6,
        description="the test's stress this target is for: sigma_n (direct_shear), sigma_3 (triaxial) [Pa]")


class CalibrationParameter(_Section):
    name: Literal["friction", "rolling_stiffness", "rolling_friction", "stiffness_ratio"] = Field(
        description="a micro-parameter of the sand material (the case's sand_material): friction mu, "
                    "rolling_stiffness beta_r, rolling_friction eta_r, stiffness_ratio k_n/k_t")
    lower: float = Field(ge=0, description="lower bound [-]")
    upper: float = Field(gt=0, description="upper bound [-]")


class CalibrationFile(_Section):
    case: str = Field(description="the direct_shear or triaxial case the search runs on (small: every evaluation "
                                  "is a run per target stress), relative to this file")
    confirm_case: Optional[str] = Field(
        default=None, description="a case of the same kind (full size) run once with the result, relative to this file")
    budget: int = Field(default=20, ge=3, le=500,
                        description="largest number of evaluations (parameter sets), the two bounds' corners included")
    targets: list[CalibrationTarget] = Field(min_length=1, max_length=20, description="[[targets]] tables")
    parameters: list[CalibrationParameter] = Field(min_length=1, max_length=4, description="[[parameters]] tables")


def load_calibration(path):
    """Read and validate a calibration file and the case files it names; returns
    ``(CalibrationFile, case path, confirm case path or None)``. Every failure is a
    CaseError naming the file, the key, the value and what is allowed."""
    path = Path(path)
    if not path.is_file():
        raise CaseError(path, "<file>", str(path), "the calibration file must exist and be a readable TOML file")
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise CaseError(path, "<syntax>", str(exc), "the file must be valid TOML (UTF-8)") from None
    try:
        spec = CalibrationFile.model_validate(raw)
    except ValidationError as exc:
        raise schema_error(path, exc, CalibrationFile) from None
    names = [p.name for p in spec.parameters]
    for i, p in enumerate(spec.parameters):
        if p.name in names[:i]:
            raise CaseError(path, f"parameters[{i}].name", p.name, "each parameter may be given once")
        if p.upper <= p.lower:
            raise CaseError(path, f"parameters[{i}].upper", p.upper,
                            f"must be above lower = {p.lower} (the bounds are reversed or equal)")
        if p.name == "stiffness_ratio" and p.lower <= 0:
            raise CaseError(path, f"parameters[{i}].lower", p.lower, "k_n/k_t must be above 0")
    cases, kinds = [], []
    for key in ("case", "confirm_case"):
        given = getattr(spec, key)
        if given is None:
            cases.append(None)
            continue
        case_path = resolve_path(path, given)
        case, _ = load_case(case_path)  # the case's own errors name the case file
        kind = case.case.kind
        if kind not in ("direct_shear", "triaxial") or (kinds and kind != kinds[0]):
            raise CaseError(path, key, given, f"must be a case of kind 'direct_shear' or 'triaxial', both cases of "
                                              f"one kind (it is '{kind}')")
        kinds.append(kind)
        for i, t in enumerate(spec.targets):
            if CALIBRATION_QUANTITY_KIND.get(t.quantity, kind) != kind:
                raise CaseError(path, f"targets[{i}].quantity", t.quantity,
                                f"a '{kind}' case does not measure it (only '{CALIBRATION_QUANTITY_KIND[t.quantity]}')")
        sand_name = getattr(case, kind).sand_material
        sand = next(m for m in case.dem.materials if m.name == sand_name)
        if "rolling_friction" in names and "rolling_stiffness" not in names and sand.rolling_stiffness == 0:
            raise CaseError(path, "parameters", "rolling_friction",
                            f"the sand of {given} has rolling_stiffness = 0, so a rolling friction does nothing: "
                            "give it a rolling_stiffness or calibrate rolling_stiffness too")
        cases.append(case_path)
    return spec, cases[0], cases[1]
