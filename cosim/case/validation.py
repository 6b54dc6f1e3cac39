"""The checks of a case beyond each field's own range, all before any computation: the sections
and keys a kind uses, and per kind the rules between fields and the files the case names
(meshes, packings, materials by name). Each failure a :class:`cosim.errors.CaseError`.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from cosim.case.messages import warn
from cosim.case.paths import mesh_path, resolve_path
from cosim.case.schema import SECTIONS_OF_KIND, Case, SpecimenSection
from cosim.errors import CaseError
from fe_domain.gmsh_text import parameter_ranges, physical_groups

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
    ("time", ("fe_safety_factor",), lambda c, s: c.case.kind not in ("coupled", "embedded"),
     "fe_safety_factor sets the explicit FE's step beside the grains (kinds coupled and embedded)"),
    ("time", ("fe_safety_factor",),
     lambda c, s: getattr(c.fe if c.case.kind == "coupled" else c.embedded, "formulation", None) == "mixed",
     "the exact limit 2/omega_max is the displacement formulation's (the mixed form's explicit pressure update has "
     "its own); set formulation = 'displacement' or use time.safety_factor"),
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
    ("specimen", ("zone_stress",), lambda c, s: c.case.kind not in ("embedded", "footing"),
     "zone_stress is for a zone fill (kinds embedded and footing)"),
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


def check_sections(path, raw):
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


def check_consistency(path, case):
    """Cross-field rules pydantic's per-field ranges cannot express: the keys the case's kind
    uses, then the kind's own rules (:data:`CHECKS_OF_KIND`)."""
    _check_used(path, case)
    CHECKS_OF_KIND[case.case.kind](path, case)
    _check_specimen_grains(path, case)


def _require(path, case, *sections):
    """The sections a kind cannot run without, present."""
    for section in sections:
        if getattr(case, section) is None:
            raise CaseError(path, section, None, f"a case of kind '{case.case.kind}' needs a [{section}] section")


def _check_run_length(path, case):
    """A dem, fe or coupled run lasts time.duration or time.steps (exactly one), and writes at
    least one row."""
    t = case.time
    if (t.duration is None) == (t.steps is None):
        raise CaseError(path, "time.duration / time.steps", (t.duration, t.steps),
                        "give exactly one of duration [s] or steps")
    if case.output.interval and t.duration and case.output.interval > t.duration:
        raise CaseError(path, "output.interval", case.output.interval,
                        f"must not exceed time.duration = {t.duration} s")


def _check_dem_case(path, case):
    _check_run_length(path, case)
    _require(path, case, "dem")
    _check_dem(path, case.dem)


def _check_fe_case(path, case):
    _check_run_length(path, case)
    _require(path, case, "fe")
    _check_fe(path, case.fe)


def _check_coupled_case(path, case):
    _check_fe_case(path, case)
    _require(path, case, "dem", "coupling")
    _check_dem(path, case.dem)
    _check_coupling(path, case)


def _check_coupling(path, case):
    """The interface of a coupled case: its material a DEM material, its groups surfaces of the mesh."""
    names = [m.name for m in case.dem.materials]
    if case.coupling.material not in names:
        raise CaseError(path, "coupling.material", case.coupling.material, f"must be one of the materials: {names}")
    mesh = mesh_path(path, case.fe.mesh)
    surfaces = sorted(n for n, d in physical_groups(mesh).items() if d == 2)
    for i, name in enumerate(case.coupling.interface):
        if name not in surfaces:
            raise CaseError(path, f"coupling.interface[{i}]", name,
                            f"not a surface physical group of {mesh.name}; available: {surfaces}")


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
    _check_clumps(path, dem)
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


def clump_templates(path, dem):
    """The [[dem.clumps]] grain shapes as :class:`de_domain.clumps.ClumpTemplate`; a template that
    breaks the rules (no member, a row that is not x, y, z, r, a radius that is not positive,
    members that do not touch) is a CaseError naming it."""
    from de_domain.clumps import ClumpTemplate
    templates = []
    for i, t in enumerate(dem.clumps):
        key = f"dem.clumps[{i}].members"
        if any(len(row) != 4 for row in t.members):
            raise CaseError(path, key, t.members, "each member is [x, y, z, r]: four numbers")
        rows = np.asarray(t.members, float)
        try:
            templates.append(ClumpTemplate(rows[:, :3], rows[:, 3]))
        except ValueError as exc:
            raise CaseError(path, key, t.members, str(exc)) from None
    return templates


def _check_clumps(path, dem):
    """[dem.particles] grains = 'clumps' with [[dem.clumps]] templates that make grains, each fitting
    the box at the largest drawn size; [[dem.clumps]] only with grains = 'clumps'."""
    p = dem.particles
    if p.grains == "spheres":
        if dem.clumps:
            raise CaseError(path, "dem.clumps", len(dem.clumps), "grain shapes need [dem.particles] grains = 'clumps'")
        return
    if p.source != "cloud":
        raise CaseError(path, "dem.particles.source", p.source, "grains = 'clumps' are made by source = 'cloud'")
    if not dem.clumps:
        raise CaseError(path, "dem.clumps", None, "grains = 'clumps' need at least one [[dem.clumps]] grain shape")
    side = min(high - low for low, high in zip(*p.box, strict=True))
    for i, template in enumerate(clump_templates(path, dem)):
        span = 2.0 * template.reach() * p.radius[1] / template.equivalent_radius()
        if span >= side:
            raise CaseError(path, f"dem.clumps[{i}].members", dem.clumps[i].members,
                            f"a grain of this shape at the largest radius {p.radius[1]} m spans {span:.3g} m, "
                            f"not less than the box's smallest side {side:.3g} m")


SPECIMEN_CLUMP_KINDS = ("direct_shear", "triaxial", "embedded", "footing")  # [specimen] may be of clumped grains


def _check_specimen_grains(path, case):
    """[specimen] grains = 'clumps' in a kind that generates its grains, with [[dem.clumps]] shapes;
    in a lab kind the largest grain fits the box (a zone's thickness is checked when the model is
    meshed: ``cosim.apps.embedded.prepare``); with source = 'file' the key is refused as unused,
    the file says what its grains are. [[dem.clumps]] in a kind without [dem.particles] only with it."""
    sp, dem, kind = case.specimen, case.dem, case.case.kind
    clumped = sp is not None and sp.grains == "clumps"
    if not clumped:
        if dem is not None and dem.clumps and dem.particles is None:
            raise CaseError(path, "dem.clumps", len(dem.clumps), "grain shapes need [specimen] grains = 'clumps'")
        return
    if kind not in SPECIMEN_CLUMP_KINDS:
        raise CaseError(path, "specimen.grains", sp.grains, f"clumped grains are made for the kinds "
                        f"{', '.join(SPECIMEN_CLUMP_KINDS)} (and 'dem' through [dem.particles]); a {kind} case "
                        "uses spheres for now")
    if not dem.clumps:
        raise CaseError(path, "dem.clumps", None, "grains = 'clumps' need at least one [[dem.clumps]] grain shape")
    if kind not in ("direct_shear", "triaxial"):
        return
    side = case.direct_shear.sample_height if kind == "direct_shear" else case.triaxial.size
    d_max = _largest_grain(path, sp)
    for i, template in enumerate(clump_templates(path, dem)):
        span = d_max * template.reach() / template.equivalent_radius()
        if span >= 0.5 * side:
            raise CaseError(path, f"dem.clumps[{i}].members", dem.clumps[i].members,
                            f"a grain of this shape at the largest sieve size {d_max * 1e3:.3g} mm spans "
                            f"{span * 1e3:.3g} mm, not less than half the specimen ({0.5e3 * side:.3g} mm); "
                            "set specimen.truncate_above or a smaller scale")


def _check_builds_its_run(path, case, lasts, time_keys, builds):
    """A kind that sets its own length (no time.duration or time.steps) and builds its grains
    and walls (no [dem.particles], no [[dem.walls]])."""
    t, dem, kind = case.time, case.dem, case.case.kind
    article = "an" if kind[0] in "aeiou" else "a"
    if t.duration is not None or t.steps is not None:
        raise CaseError(path, "time.duration / time.steps", (t.duration, t.steps),
                        f"{article} {kind} run lasts {lasts}; give only {time_keys}")
    if dem.particles is not None:
        raise CaseError(path, "dem.particles", "present", f"{article} {kind} case {builds}; remove [dem.particles]")
    if dem.walls:
        raise CaseError(path, "dem.walls", len(dem.walls), f"{article} {kind} case {builds}; remove [[dem.walls]]")


def _check_direct_shear(path, case):
    """A direct shear case: [dem] materials, [specimen], [direct_shear]; the run length
    follows from the shear distance, so [time] only sets dt / safety_factor."""
    _require(path, case, "dem", "specimen", "direct_shear")
    _check_builds_its_run(path, case, "until direct_shear.shear_distance", "time.dt or time.safety_factor",
                          "builds its grains from [specimen] and the shear box itself")
    dem, sp, ds = case.dem, case.specimen, case.direct_shear
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
    _require(path, case, "dem", "specimen", "triaxial")
    _check_builds_its_run(path, case, "until triaxial.axial_strain", "time.dt or time.safety_factor",
                          "builds its grains from [specimen] and its walls itself")
    dem, sp, tx = case.dem, case.specimen, case.triaxial
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
    _require(path, case, "dem", "specimen", "footing", "soil", "zone")
    _check_builds_its_run(path, case, "until footing.settlement", "time.safety_factor",
                          "builds its grains from [specimen] and its walls and footing itself")
    dem, sp, ft, soil, zone = case.dem, case.specimen, case.footing, case.soil, case.zone
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
    _require(path, case, "dem", "specimen", "embedded")
    _check_builds_its_run(path, case, "embedded.loading_time after the rest", "time.safety_factor",
                          "takes its grains from [specimen] and its walls from the model")
    dem, sp, em = case.dem, case.specimen, case.embedded
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


#: the rules of each kind of case, after its keys are known to be used
CHECKS_OF_KIND = {
    "dem": _check_dem_case,
    "fe": _check_fe_case,
    "coupled": _check_coupled_case,
    "direct_shear": _check_direct_shear,
    "triaxial": _check_triaxial,
    "footing": _check_footing,
    "embedded": _check_embedded,
}
