"""What the ``embedded`` kind's models share (:mod:`cosim.apps.embedded` — the coupled model and
its all-DEM twin —, :mod:`cosim.apps.embedded_fe` — the FE-only twin — and the report,
:mod:`cosim.apps.embedded_report`): the roles of the model's groups, the loading's ramp, the
grains' materials, the FE volumes with their supports and initial stress, and the linings'
gauges and sections. Kept apart so that the run and its twins import it, not each other."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cosim.outputs import atomic_write_text, is_root

AXES = "xyz"


@dataclass(frozen=True)
class Roles:
    """The groups of the case by what they are in this model: grain volumes, FE volumes
    {group: EmbeddedVolume}, surfaces {group: EmbeddedSurface}, rigid bodies."""
    grains: list
    fe: dict
    surfaces: dict
    rigid: list

    @classmethod
    def of(cls, em):
        if em.model == "fe":  # the zones are soil like the first 'soil' volume
            soil = next(v for v in em.volumes if v.role == "soil")
            fe = {v.group: soil.model_copy(update={"group": v.group}) if v.role == "zone" else v for v in em.volumes}
            return cls([], fe, {s.group: s for s in em.surfaces}, [])
        grains = [v.group for v in em.volumes if v.role == "zone" or (v.role == "soil" and em.model == "dem")]
        fe = {v.group: v for v in em.volumes if v.group not in grains}
        return cls(grains, fe, {s.group: s for s in em.surfaces}, list(em.rigid))


class LoadingRamp:
    """A load's amplitude that is 0 until the loading starts, then rises linearly to 1 over the
    loading: ``start`` is set when the loading starts (or from the checkpoint on resume)."""

    def __init__(self, duration):
        self.duration, self.start = duration, None

    def __call__(self, t):
        return 0.0 if self.start is None else min(max((t - self.start) / self.duration, 0.0), 1.0)

def roller_axis(triangles):
    """The axis (0, 1, 2) every triangle of a surface is normal to, or None."""
    n = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    n = n / np.linalg.norm(n, axis=1)[:, None]
    for axis in range(3):
        if np.all(np.abs(np.abs(n[:, axis]) - 1.0) < 1e-6):
            return axis
    return None

def grain_materials(case):
    from cosim.apps.dem import materials_of
    em = case.embedded
    names = [em.sand_material, em.interface_material, em.lid_material] + [m.name for m in case.dem.materials]
    mats, *ids = materials_of(case.dem, *names)
    return mats, {name: i for name, i in zip(names, ids, strict=True)}

def build_fe(case, split, roles, bulk_density, ramp=None):
    """The FE volumes on the split mesh: a material per volume (soil without ρ: the packing's
    bulk density), supports from the surfaces' ``fe`` roles, gravity, the geostatic stress of
    the soil volumes given K0 (:func:`geostatic_loads`), the linings' contraction over the
    loading (amplitude ``ramp``, :class:`LoadingRamp`), local damping."""
    from fe_domain.boundary import Contraction
    from fe_domain.build import build_solid
    from fe_domain.explicit import stable_alpha_tau
    materials = {g: {"E": v.E, "nu": v.nu, "rho": v.rho or bulk_density, "inertia_scale": v.inertia_scale}
                 for g, v in roles.fe.items()}
    supports = []
    for group, s in roles.surfaces.items():
        if group not in split.fe.groups or s.fe == "free":
            continue
        components = [0, 1, 2] if s.fe == "fixed" else [roller_axis(split.surfaces[group])]
        supports.append({"type": "fixed", "boundary": group, "components": components})
    nu = max(v.nu for v in roles.fe.values())
    gravity = {"type": "body_force", "acceleration": list(case.dem.gravity)}
    return build_solid(split.fe, material=materials, boundary_conditions=supports,
                       loads=[gravity, *geostatic_loads(case, split, roles),
                              *[Contraction(0.5 * lining.volume_loss, lining.axis, (lining.volume,), ramp)
                                for lining in case.embedded.linings if lining.volume_loss > 0]],
                       damping={"type": "local", "alpha": case.embedded.damping} if case.embedded.damping else None,
                       formulation=case.embedded.formulation, alpha_tau=stable_alpha_tau(nu),
                       safety_factor=case.time.safety_factor)


def geostatic_loads(case, split, roles):
    """The initial stress of each FE soil volume given K0 (``fe_domain.build`` "geostatic"
    tables): level ground through the model's highest point along −g (of the zone and the FE
    soil volumes, every rank's), the overburden of the volume's own density."""
    from mpi4py import MPI
    given = {group: v.K0 for group, v in roles.fe.items() if v.role == "soil" and v.K0 is not None}
    if not given:
        return []
    up = -np.asarray(case.dem.gravity, dtype=float) / np.linalg.norm(case.dem.gravity)
    coordinates = split.fe.mesh.geometry.x
    cells = np.concatenate([split.fe.cells(g) for g in given])
    vertices = split.fe.mesh.geometry.dofmap.array.reshape(-1, 4)[cells].ravel()
    heights = [coordinates[vertices] @ up, split.zone.tets.reshape(-1, 3) @ up]
    local = max((float(h.max()) for h in heights if len(h)), default=-np.inf)
    height = split.fe.mesh.comm.allreduce(local, op=MPI.MAX)
    ground = list(height * up)
    return [{"type": "geostatic", "acceleration": list(case.dem.gravity), "ground": ground, "K0": k0,
             "groups": [group]} for group, k0 in given.items()]

#: where series.csv reads each lining's thrust and moment: degrees from the crown
LINING_GAUGES = {"crown": 5.0, "springline": 90.0, "invert": 175.0}
LINING_SPACING = 5.0  # degrees between the cuts of <volume>_sections.csv


@dataclass(frozen=True)
class LiningGauge:
    """What is read from a lining each row: its section forces and its diameters
    (:class:`fe_domain.lining.SectionGauge`, :class:`fe_domain.lining.DiameterGauge`)."""
    sections: object
    diameters: object

    @property
    def ring(self):
        return self.sections.ring

    def row(self):
        """The lining's values of a series.csv row (:func:`lining_columns`); collective."""
        forces = self.sections.forces(list(LINING_GAUGES.values()))
        return [*forces.thrust, *forces.moment, *self.diameters.changes()]


def lining_gauges(case, solid):
    """A :class:`LiningGauge` per lining of ``solid`` (its ring found from its cells, θ from the
    crown, up = −g); collective."""
    from fe_domain.lining import DiameterGauge, SectionGauge, ring_of_cells
    up = -np.asarray(case.dem.gravity, float)
    gauges = []
    for lining in case.embedded.linings:
        ring = ring_of_cells(solid, lining.volume, lining.centre, lining.axis, up)
        gauges.append(LiningGauge(SectionGauge(solid, lining.volume, ring), DiameterGauge(solid, lining.volume, ring)))
    return gauges

def lining_columns(linings):
    """series.csv columns of the linings: thrust and moment at each of :data:`LINING_GAUGES`, the
    change of the vertical and horizontal inside diameters over the diameter (lengthening +)."""
    return [name for lining in linings for name in
            [f"{lining.volume}_{q}_{where}" for q in ("thrust", "moment") for where in LINING_GAUGES]
            + [f"{lining.volume}_diameter_change_{d}" for d in ("vertical", "horizontal")]]

def sections(gauge):
    """{angle_deg, thrust, moment} lists of a lining every LINING_SPACING degrees; collective."""
    forces = gauge.sections.forces(gauge.sections.angles_deg(LINING_SPACING))
    return {"angle_deg": forces.angle_deg.tolist(), "thrust": forces.thrust.tolist(), "moment": forces.moment.tolist()}


def write_sections(path, at_rest, end):
    """<volume>_sections.csv (rank 0): per cut angle from the crown the thrust (N/m, compression +)
    and moment (N·m/m, intrados in tension +) at rest and at the end of the loading."""
    if not is_root():
        return
    header = "angle_deg,thrust_at_rest,moment_at_rest,thrust_end,moment_end\n"
    lines = [f"{a:.6g},{n0:.9g},{m0:.9g},{n1:.9g},{m1:.9g}" for a, n0, m0, n1, m1 in
             zip(end["angle_deg"], at_rest["thrust"], at_rest["moment"], end["thrust"], end["moment"], strict=True)]
    atomic_write_text(path, header + "\n".join(lines) + "\n")


REST_STRESS_COLUMNS = ("z_top_m", "z_bottom_m", "volume_m3", "sigma_xx_Pa", "sigma_yy_Pa", "sigma_zz_Pa",
                       "sigma_xz_Pa", "K_x", "K_y")


@dataclass(frozen=True)
class Band:
    """A horizontal band of the grain volume (a Love–Weber region): the contact points with
    ``bottom`` ≤ z < ``top``; ``volume`` its part of the grain volume (m³)."""
    top: float
    bottom: float
    volume: float

    def contains(self, points):
        return (points[:, 2] >= self.bottom) & (points[:, 2] < self.top)


def _tet_volumes(a, b, c, d):
    return np.abs(np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a)) / 6.0


def volume_below(tets, level):
    """The volume (m³) of the tetrahedra (k, 4, 3) below the plane z = ``level``, exactly: per
    tetrahedron with its corners sorted by height, one corner below keeps the tetrahedron cut off
    at that corner (volume V t₁ t₂ t₃, t the edges' fractions below the plane), three below lose
    the one cut off at the corner above, and two below keep a prism (corners a, b below, its
    edges' crossings on the plane), cut into three tetrahedra."""
    order = np.argsort(tets[:, :, 2], axis=1, kind="stable")
    t = np.take_along_axis(tets, order[:, :, None], axis=1)
    h = t[:, :, 2] - level
    below = np.count_nonzero(h <= 0.0, axis=1)
    whole = _tet_volumes(*(t[:, k] for k in range(4)))
    total = float(np.sum(whole[below == 4]))

    def crossing(rows, i, j):  # where edge i–j of the sorted corners meets the plane
        f = h[rows, i] / (h[rows, i] - h[rows, j])
        return t[rows, i] + f[:, None] * (t[rows, j] - t[rows, i])

    one = below == 1
    total += float(np.sum(whole[one] * np.prod(h[one, :1] / (h[one, :1] - h[one, 1:]), axis=1)))
    three = below == 3
    total += float(np.sum(whole[three] * (1.0 - np.prod(h[three, 3:] / (h[three, 3:] - h[three, :3]), axis=1))))
    rows = np.flatnonzero(below == 2)
    a, b = t[rows, 0], t[rows, 1]
    p, q, r, u = crossing(rows, 0, 2), crossing(rows, 0, 3), crossing(rows, 1, 2), crossing(rows, 1, 3)
    total += float(np.sum(_tet_volumes(a, p, q, b) + _tet_volumes(p, q, b, r) + _tet_volumes(q, b, r, u)))
    return total


def stress_bands(tets, height):
    """The grain volume (tetrahedra (k, 4, 3)) cut into horizontal bands of about ``height``
    from its top down, the last one reaching its bottom; the first band also takes every
    contact above the top, the last every one below the bottom; each with its volume."""
    z = tets[:, :, 2]
    top, bottom = float(z.max()), float(z.min())
    count = max(1, int(round((top - bottom) / height)))
    cuts = top - (top - bottom) * np.arange(count + 1) / count
    below = [volume_below(tets, c) for c in cuts]
    cuts[0], cuts[-1] = np.inf, -np.inf
    return [Band(float(cuts[k]), float(cuts[k + 1]), below[k] - below[k + 1]) for k in range(count)]


def rest_stress(engine, bands):
    """The grains' stress at rest by band: σ = 1/V Σ_c f_c ⊗ l_c over the contacts in the band
    (:func:`de_domain.diagnostics.love_weber_stress`, compression +; the supports' contacts
    included) and the ratios K_x = σ_xx / σ_zz, K_y = σ_yy / σ_zz (the earth pressure coefficient
    at rest, K0 of an undisturbed level ground, where gravity is along z); and over the whole
    grain volume, σ = Σ V_b σ_b / Σ V_b. Returns (CSV rows, {K_x, K_y, sigma_zz_Pa}); collective."""
    from de_domain.diagnostics import love_weber_stress
    rows, total, volume = [], np.zeros((3, 3)), 0.0
    for band in bands:
        sigma = love_weber_stress(engine, band) if band.volume > 0 else np.zeros((3, 3))
        total += band.volume * sigma
        volume += band.volume
        k = [sigma[0, 0] / sigma[2, 2], sigma[1, 1] / sigma[2, 2]] if sigma[2, 2] > 0 else [np.nan, np.nan]
        rows.append([band.top, band.bottom, band.volume, sigma[0, 0], sigma[1, 1], sigma[2, 2],
                     0.5 * (sigma[0, 2] + sigma[2, 0]), *k])
    sigma = total / volume
    return rows, {"K_x": float(sigma[0, 0] / sigma[2, 2]), "K_y": float(sigma[1, 1] / sigma[2, 2]),
                  "sigma_zz_Pa": float(sigma[2, 2])}
