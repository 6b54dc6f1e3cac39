"""Build an ExplicitSolid from plain parameters (numbers, strings, lists, dicts).

This is the entry point for a case loader: it takes already-parsed values (e.g. a
TOML table) and returns the solver; it reads no files besides the mesh.  Tables::

    material   {"E": 1e7, "nu": 0.3, "rho": 1800}  or  {"<cell group>": {...}, ...}
               (optional "inertia_scale": mass scaling of that material, Material)
    boundary_conditions  [{"type": "fixed", "boundary": "bottom", "components": [2]},
                          {"type": "velocity", "boundary": "left", "velocity": [1e-3, 0, 0],
                           "components": [0], "ramp": 0.01}]
    loads      [{"type": "traction", "boundary": "top", "traction": [0, 0, -1e4], "ramp": 0.01},
                {"type": "pressure", "boundary": "top", "pressure": 1e4},
                {"type": "body_force", "acceleration": [0, 0, -9.81]},
                {"type": "geostatic", "acceleration": [0, 0, -9.81], "ground": [0, 0, 0.5],
                 "K0": 0.5, "groups": ["soil"]}]   (the initial stress at rest, GeostaticStress)
    damping    {"type": "local", "alpha": 0.7}  or  {"type": "mass", "alpha": 50.0}

``components`` default to all three; ``ramp`` (s) makes the amplitude rise linearly
from 0 to 1 over that time (default: constant). A load may also be given as its record of
``fe_domain.boundary`` (e.g. a ``Contraction`` with an amplitude of its own).
"""

from __future__ import annotations

from mpi4py import MPI

from fe_domain.boundary import (
    BodyForce,
    Fixed,
    GeostaticStress,
    LocalNonViscousDamping,
    MassProportionalDamping,
    Material,
    NormalPressure,
    PrescribedVelocity,
    Traction,
    constant,
    ramp,
)
from fe_domain.explicit import DEFAULT_ALPHA_TAU, ExplicitSolid
from fe_domain.mesh import TaggedMesh, load_mesh

DAMPING_LAWS = {"local": LocalNonViscousDamping, "mass": MassProportionalDamping}


def build_solid(mesh: str | TaggedMesh, mesh_size: float | None = None, *, material: dict,
                boundary_conditions: list[dict] = (), loads: list[dict] = (),
                damping: dict | None = None, formulation: str = "mixed",
                alpha_tau: float = DEFAULT_ALPHA_TAU, safety_factor: float = 0.5,
                geometry_parameters: dict[str, float] | None = None,
                comm: MPI.Comm = MPI.COMM_WORLD) -> ExplicitSolid:
    """Mesh ``mesh`` (.geo with ``mesh_size``, or .msh; or take an already made TaggedMesh) and
    build the solver; see module docstring."""
    records = dict(boundary_conditions=[_boundary_condition(i, bc) for i, bc in enumerate(boundary_conditions)],
                   loads=[_load(i, load) for i, load in enumerate(loads)], damping=_damping(damping))
    solid_material = _material(material)            # tables are checked before meshing
    tagged = mesh if isinstance(mesh, TaggedMesh) else load_mesh(mesh, mesh_size, comm, geometry_parameters)
    return ExplicitSolid(tagged, solid_material, formulation=formulation, alpha_tau=alpha_tau,
                         safety_factor=safety_factor, **records)


def _material(table: dict):
    if {"E", "nu", "rho"} <= set(table):
        return Material(E=table["E"], nu=table["nu"], rho=table["rho"], inertia_scale=table.get("inertia_scale", 1.0))
    return {group: _material(sub) for group, sub in table.items()}


def _amplitude(table: dict):
    return ramp(table["ramp"]) if "ramp" in table else constant


def _boundary_condition(index: int, table: dict):
    kind = table.get("type")
    components = tuple(table.get("components", (0, 1, 2)))
    if kind == "fixed":
        return Fixed(table["boundary"], components)
    if kind == "velocity":
        velocity = [table["velocity"][c] if c in components else None for c in range(3)]
        return PrescribedVelocity(table["boundary"], velocity, _amplitude(table))
    raise ValueError(f"boundary_conditions[{index}].type = {kind!r}: must be 'fixed' or 'velocity'")


def _load(index: int, table):
    if not isinstance(table, dict):   # a record of fe_domain.boundary, given as is
        return table
    kind = table.get("type")
    if kind == "traction":
        return Traction(table["boundary"], table["traction"], _amplitude(table))
    if kind == "pressure":
        return NormalPressure(table["boundary"], table["pressure"], _amplitude(table))
    if kind == "body_force":
        return BodyForce(table["acceleration"], _amplitude(table))
    if kind == "geostatic":
        return GeostaticStress(table["acceleration"], table["ground"], table["K0"], tuple(table["groups"]))
    raise ValueError(f"loads[{index}].type = {kind!r}: must be 'traction', 'pressure', 'body_force' or 'geostatic'")


def _damping(table: dict | None):
    if table is None:
        return None
    kind = table.get("type")
    if kind not in DAMPING_LAWS:
        raise ValueError(f"damping.type = {kind!r}: must be one of {sorted(DAMPING_LAWS)}")
    return DAMPING_LAWS[kind](table["alpha"])
