"""Walls: infinite planes and triangle facet meshes (docs/design.md §2.9–2.10, §5.1).

Both are two-body contacts with a sphere i and the wall as body j: the wall is
rigid, infinitely massive (m* = m_i) and, for the linear law, treated as a mirror
sphere of the same material radius (k_n = k_i k_w/(k_i + k_w), k = 4 E r, i.e.
2 E r for equal E); for Hertz R* = r_i (sphere on a half space).

Facet meshes: a sphere gets one contact per triangle whose closest point lies
within its radius, except that edge and vertex contacts are deduplicated inside
one mesh (docs/design.md §2.10: exactly one contact at a shared edge or vertex):
  * an edge contact is dropped if the sphere has a face contact with a triangle
    incident to that edge, or an edge contact on the same edge with a triangle
    of lower index;
  * a vertex contact is dropped if the sphere has a face or edge contact with a
    triangle containing that vertex, or a vertex contact on the same vertex with
    a triangle of lower index.
The force a sphere exerts on a triangle is split on its vertices with the
barycentric coordinates of the closest point (−λ_a F, docs/design.md §5.1).
"""
from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import njit

from .contact_laws import (
    ContactBodies,
    ContactGeometry,
    RelativeMotion,
    Springs,
    contact_force,
    linear_normal_stiffness,
    released_energy,
)
from .state import E_FRICTION, W_CONTACT, W_WORK

#: the closest point of a triangle to a sphere's centre: the point, its barycentric weights and
#: the feature it lies on (closest_point_on_triangle)
ClosestPoint = namedtuple("ClosestPoint", "x y z la lb lc feature")
#: the features of a triangle abc, in the order the deduplication rule and the triangle's
#: edge (ab, bc, ca) and vertex (a, b, c) tables index by
FACE, EDGE_AB, EDGE_BC, EDGE_CA, VERTEX_A, VERTEX_B, VERTEX_C = range(7)
#: a sphere as its contacts with walls and facets read it: material, radius, mass, velocity
#: v^{n−½}, spin ω^{n−½}, last acceleration (scalars: no array views per contact)
SphereState = namedtuple("SphereState", "material radius mass vx vy vz wx wy wz ax ay az")


class PlaneWall:
    """Infinite plane through ``point`` with unit ``normal`` pointing to the particle side.

    ``velocity`` is a rigid translation applied by the engine each step (x += v Δt).
    ``point`` may also be set (or edited in place) between steps; the jump is booked as
    boundary work with the previous step's force. ``force``: total force the particles
    exert on the wall in the last step.

    ``point``, ``normal`` and ``velocity`` are (3,) arrays that setting overwrites in
    place; an engine stores them as rows of its own wall arrays (:meth:`bind`), which
    its kernels read and advance directly: nothing is copied between the walls and
    the engine at each run.
    """

    def __init__(self, point, normal, material=0, velocity=(0.0, 0.0, 0.0)):
        normal = np.array(normal, dtype=np.float64).reshape(3)
        norm = np.linalg.norm(normal)
        if norm == 0.0:
            raise ValueError("PlaneWall: 'normal' must be a non-zero vector")
        self._point = np.array(point, dtype=np.float64).reshape(3)
        self._normal = normal / norm
        self._velocity = np.array(velocity, dtype=np.float64).reshape(3)
        self._material = np.array([material], dtype=np.int32)
        self.force = np.zeros(3)
        self.bound_to, self.bound_row = None, -1  # the wall arrays holding this wall's state

    def bind(self, arrays, row):
        """Keep the state in row ``row`` of ``arrays`` = (point, normal, velocity, material)
        (an engine's), the current values copied there."""
        point, normal, velocity, material = arrays
        point[row], normal[row], velocity[row], material[row] = self._point, self._normal, self._velocity, \
            self._material[0]
        self._point, self._normal, self._velocity = point[row], normal[row], velocity[row]
        self._material = material[row:row + 1]
        self.bound_to, self.bound_row = arrays, row

    @property
    def point(self):
        return self._point

    @point.setter
    def point(self, value):
        self._point[:] = np.asarray(value, dtype=np.float64).reshape(3)

    @property
    def normal(self):
        return self._normal

    @normal.setter
    def normal(self, value):
        self._normal[:] = np.asarray(value, dtype=np.float64).reshape(3)

    @property
    def velocity(self):
        return self._velocity

    @velocity.setter
    def velocity(self, value):
        self._velocity[:] = np.asarray(value, dtype=np.float64).reshape(3)

    @property
    def material(self):
        return int(self._material[0])

    @material.setter
    def material(self, value):
        self._material[0] = int(value)


class FacetMesh:
    """Triangle mesh wall (two-sided). ``vertices`` (nv, 3), ``triangles`` (nt, 3) int.

    Motion: fixed (zero velocity), rigid ``velocity = (vx, vy, vz)``, or per-vertex
    state from outside via :meth:`set_vertex_state`; the engine advances the
    vertices linearly, x += v Δt, after every step (docs/design.md §5.3).

    After each step: ``vertex_force`` (nv, 3) the force the particles exert on each
    vertex (barycentric split), ``vertex_impulse`` its time integral since the last
    :meth:`reset_impulse`, ``force`` the total on the mesh.
    """

    def __init__(self, vertices, triangles, material=0, source_nodes=None):
        self.vertices = np.array(vertices, dtype=np.float64).reshape(-1, 3)
        self.triangles = np.array(triangles, dtype=np.int32).reshape(-1, 3)
        nv = self.vertices.shape[0]
        if self.triangles.size and (self.triangles.min() < 0 or self.triangles.max() >= nv):
            raise ValueError(f"FacetMesh: triangle vertex ids must be in [0, {nv - 1}]")
        self.material = int(material)
        self.vertex_velocity = np.zeros((nv, 3))
        self.vertex_force = np.zeros((nv, 3))
        self.vertex_impulse = np.zeros((nv, 3))
        self.force = np.zeros(3)
        self.source_nodes = None if source_nodes is None else np.asarray(source_nodes, dtype=np.int64)
        self.triangle_edges, self.n_edges = _edge_ids(self.triangles)

    @property
    def velocity(self):
        """Mean vertex velocity; setting it prescribes a rigid translation."""
        return self.vertex_velocity.mean(axis=0) if len(self.vertex_velocity) else np.zeros(3)

    @velocity.setter
    def velocity(self, value):
        self.vertex_velocity[:] = np.asarray(value, dtype=np.float64).reshape(3)

    def set_vertex_state(self, positions, velocities):
        """Set every vertex position and velocity (e.g. the FE interface, docs/design.md §5.3)."""
        self.vertices[:] = np.asarray(positions, dtype=np.float64).reshape(self.vertices.shape)
        self.vertex_velocity[:] = np.asarray(velocities, dtype=np.float64).reshape(self.vertices.shape)

    def reset_impulse(self):
        self.vertex_impulse[:] = 0.0

    @classmethod
    def from_file(cls, path, material=0, physical=None):
        """STL (``.stl``) or gmsh (``.msh``, optional physical tag) by file suffix."""
        if str(path).lower().endswith(".stl"):
            return cls.from_stl(path, material)
        return cls.from_gmsh(path, physical, material)

    @classmethod
    def from_stl(cls, path, material=0):
        """Read an STL surface with meshio, merging duplicated vertices."""
        import meshio

        mesh = meshio.read(path)
        tris = np.concatenate([c.data for c in mesh.cells if c.type == "triangle"])
        points, inverse = np.unique(mesh.points[tris.ravel()], axis=0, return_inverse=True)
        return cls(points, inverse.reshape(-1, 3), material)

    @classmethod
    def from_gmsh(cls, path, physical=None, material=0):
        """Read the triangles of a gmsh .msh (optionally one physical tag) via meshio.

        ``source_nodes`` keeps each vertex's node index in the file (for the FE map).
        """
        import meshio

        mesh = meshio.read(path)
        blocks = []
        for k, cell in enumerate(mesh.cells):
            if cell.type != "triangle":
                continue
            data = cell.data
            if physical is not None:
                tags = mesh.cell_data["gmsh:physical"][k]
                data = data[tags == physical]
            blocks.append(data)
        if not blocks or sum(len(b) for b in blocks) == 0:
            raise ValueError(f"FacetMesh.from_gmsh: no triangles in {path!r} (physical={physical!r})")
        tris = np.concatenate(blocks)
        used, inverse = np.unique(tris.ravel(), return_inverse=True)
        return cls(mesh.points[used, :3], inverse.reshape(-1, 3), material, source_nodes=used)


def _edge_ids(triangles):
    """Edge id of edge k (vertices k, k+1) of every triangle; shared edges share ids."""
    if triangles.shape[0] == 0:
        return np.zeros((0, 3), np.int64), 0
    a = triangles[:, [0, 1, 2]].ravel()
    b = triangles[:, [1, 2, 0]].ravel()
    keys = np.stack([np.minimum(a, b), np.maximum(a, b)], axis=1)
    _, inverse = np.unique(keys, axis=0, return_inverse=True)
    return inverse.reshape(-1, 3).astype(np.int64), int(inverse.max()) + 1


@njit(cache=True, error_model="numpy")
def point_triangle_distance2(px, py, pz, a, b, c):
    """Squared distance from a point to triangle abc (Ericson, RTCD §5.1.5)."""
    q = closest_point_on_triangle(px, py, pz, a, b, c)
    return (q.x - px) ** 2 + (q.y - py) ** 2 + (q.z - pz) ** 2


@njit(cache=True, error_model="numpy")
def closest_point_on_triangle(px, py, pz, a, b, c):
    """Closest point of triangle abc to p, its barycentric weights and its feature.

    Ericson, Real-Time Collision Detection §5.1.5. Returns a ``ClosestPoint``: the point, its
    weights (la, lb, lc) and its feature (``FACE``, ``EDGE_AB`` … ``VERTEX_C``).
    """
    abx = b[0] - a[0]; aby = b[1] - a[1]; abz = b[2] - a[2]
    acx = c[0] - a[0]; acy = c[1] - a[1]; acz = c[2] - a[2]
    apx = px - a[0]; apy = py - a[1]; apz = pz - a[2]
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    if d1 <= 0.0 and d2 <= 0.0:
        return ClosestPoint(a[0], a[1], a[2], 1.0, 0.0, 0.0, VERTEX_A)
    bpx = px - b[0]; bpy = py - b[1]; bpz = pz - b[2]
    d3 = abx * bpx + aby * bpy + abz * bpz
    d4 = acx * bpx + acy * bpy + acz * bpz
    if d3 >= 0.0 and d4 <= d3:
        return ClosestPoint(b[0], b[1], b[2], 0.0, 1.0, 0.0, VERTEX_B)
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        return ClosestPoint(a[0] + v * abx, a[1] + v * aby, a[2] + v * abz, 1.0 - v, v, 0.0, EDGE_AB)
    cpx = px - c[0]; cpy = py - c[1]; cpz = pz - c[2]
    d5 = abx * cpx + aby * cpy + abz * cpz
    d6 = acx * cpx + acy * cpy + acz * cpz
    if d6 >= 0.0 and d5 <= d6:
        return ClosestPoint(c[0], c[1], c[2], 0.0, 0.0, 1.0, VERTEX_C)
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        return ClosestPoint(a[0] + w * acx, a[1] + w * acy, a[2] + w * acz, 1.0 - w, 0.0, w, EDGE_CA)
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return ClosestPoint(b[0] + w * (c[0] - b[0]), b[1] + w * (c[1] - b[1]), b[2] + w * (c[2] - b[2]),
                            0.0, 1.0 - w, w, EDGE_BC)
    denom = 1.0 / (va + vb + vc)
    v = vb * denom
    w = vc * denom
    return ClosestPoint(a[0] + abx * v + acx * w, a[1] + aby * v + acy * w, a[2] + abz * v + acz * w,
                        1.0 - v - w, v, w, FACE)


@njit(cache=True, error_model="numpy")
def release_springs(law, pair_params, a, b, k_linear, r, history, energy):
    """A sphere–surface contact that has opened: the elastic energy left in its springs
    (``history``: tangential force, rolling moment) booked as friction in ``energy`` and the
    springs zeroed (contact_laws.released_energy)."""
    if (history[0] != 0.0 or history[1] != 0.0 or history[2] != 0.0 or history[3] != 0.0 or history[4] != 0.0
            or history[5] != 0.0):
        springs = Springs(history[0], history[1], history[2], history[3], history[4], history[5])
        energy[W_CONTACT + E_FRICTION] += released_energy(law, pair_params, a, b, k_linear, r, springs)
        for k in range(6):
            history[k] = 0.0


@njit(cache=True, error_model="numpy")
def sphere_on_surface(law, dt, pair_params, sphere, b, k_linear, geometry, vsx, vsy, vsz, history, energy):
    """One contact of a sphere (``sphere``: a :data:`SphereState`) with a rigid surface of
    material ``b`` (a plane wall or a facet) whose contact point moves at (vsx, vsy, vsz): the
    contact point's velocity on the sphere at the arm r − δ/2 along n (``geometry``, n from the
    sphere to the surface), the law (contact_laws.contact_force; the surface is body j:
    infinite mass, no spin), the springs written back to ``history``, and in ``energy``
    (``state.W_*``) the surface's work on the sphere and the contact's energy terms. Returns
    the force on the sphere and its torque about the centre, (arm n) × F + M_r."""
    nx, ny, nz, overlap = geometry
    r = sphere.radius
    arm = r - 0.5 * overlap
    vcx = sphere.vx + arm * (sphere.wy * nz - sphere.wz * ny)
    vcy = sphere.vy + arm * (sphere.wz * nx - sphere.wx * nz)
    vcz = sphere.vz + arm * (sphere.wx * ny - sphere.wy * nx)
    dvn = -0.5 * dt * (sphere.ax * nx + sphere.ay * ny + sphere.az * nz)
    res = contact_force(law, pair_params, sphere.material, b, geometry,
                        RelativeMotion(vsx - vcx, vsy - vcy, vsz - vcz, dvn, -sphere.wx, -sphere.wy, -sphere.wz),
                        ContactBodies(k_linear, r, r, sphere.mass),
                        Springs(history[0], history[1], history[2], history[3], history[4], history[5]), dt)
    fx, fy, fz = res.fx, res.fy, res.fz
    for k in range(6):
        history[k] = res.springs[k]
    energy[W_WORK] += (fx * vsx + fy * vsy + fz * vsz) * dt
    for k in range(5):
        energy[W_CONTACT + k] += res.energy[k]
    return (fx, fy, fz, arm * (ny * fz - nz * fy) + res.springs.mrx, arm * (nz * fx - nx * fz) + res.springs.mry,
            arm * (nx * fy - ny * fx) + res.springs.mrz)


@njit(cache=True, error_model="numpy")
def sphere_state(particles, i):
    """The :data:`SphereState` of sphere ``i``, read once for all its surface contacts."""
    vel, angvel, accel = particles.vel, particles.angvel, particles.accel
    return SphereState(particles.material[i], particles.radius[i], particles.mass[i], vel[i, 0], vel[i, 1],
                       vel[i, 2], angvel[i, 0], angvel[i, 1], angvel[i, 2], accel[i, 0], accel[i, 1], accel[i, 2])


@njit(cache=True, error_model="numpy")
def plane_wall_contacts(first, last, settings, particles, params, perm, walls, energy):
    """Contacts of the owned spheres of perm positions [first, last) with their
    plane-wall candidates, ``walls.start[s]:walls.start[s + 1]`` in ascending wall index.

    The wall is body j (module docstring): n = −(wall normal), δ = r − (x − x_w)·n_w,
    contact point on the sphere at the arm r − δ/2, the wall's velocity its rigid
    translation. The contact forces and torques are added, in candidate order, to
    ``particles.force``/``torque``; per candidate the history, normal force and force
    on the sphere are stored; ``energy`` (``state.W_*``) += the walls' work on the
    spheres and the contact energy terms. An opened contact releases its springs
    (booked as friction). One call per block of particles: the named tuples are
    unpacked once per block, not per particle (each unpacked array costs a
    reference-count increment and decrement, atomic, shared by the threads).
    """
    law = settings.law
    dt = settings.dt
    pos = particles.pos
    material = particles.material
    young = params.young
    pair_params = params.pair_params
    wall_point = walls.point
    wall_normal = walls.normal
    wall_vel = walls.velocity
    wall_mat = walls.material
    w_start = walls.start
    w_idx = walls.wall
    w_hist = walls.history
    w_fn = walls.normal_force
    w_force = walls.force
    radius = particles.radius
    force = particles.force
    torque = particles.torque
    ghost = particles.ghost
    for s in range(first, last):
        i = np.uint64(s) if settings.in_order else np.uint64(perm[s])
        if ghost[i] or w_start[s + 1] == w_start[s]:
            continue
        fx = force[i, 0]; fy = force[i, 1]; fz = force[i, 2]
        tx = torque[i, 0]; ty = torque[i, 1]; tz = torque[i, 2]
        r = radius[i]
        sphere = sphere_state(particles, i)
        for c in range(w_start[s], w_start[s + 1]):
            w = w_idx[c]
            dist = 0.0
            for d in range(3):
                dist += (pos[i, d] - wall_point[w, d]) * wall_normal[w, d]
            overlap = r - dist
            k_lin = linear_normal_stiffness(young[material[i]], r, young[wall_mat[w]], r)
            if overlap <= 0.0:
                release_springs(law, pair_params, material[i], wall_mat[w], k_lin, r, w_hist[c], energy)
                w_fn[c] = 0.0
                for k in range(3):
                    w_force[c, k] = 0.0
                continue
            nx = -wall_normal[w, 0]
            ny = -wall_normal[w, 1]
            nz = -wall_normal[w, 2]
            wfx, wfy, wfz, wtx, wty, wtz = sphere_on_surface(
                law, dt, pair_params, sphere, wall_mat[w], k_lin, ContactGeometry(nx, ny, nz, overlap),
                wall_vel[w, 0], wall_vel[w, 1], wall_vel[w, 2], w_hist[c], energy)
            w_fn[c] = -(wfx * nx + wfy * ny + wfz * nz)
            w_force[c, 0] = wfx
            w_force[c, 1] = wfy
            w_force[c, 2] = wfz
            fx += wfx
            fy += wfy
            fz += wfz
            tx += wtx
            ty += wty
            tz += wtz
        force[i, 0] = fx; force[i, 1] = fy; force[i, 2] = fz
        torque[i, 0] = tx; torque[i, 1] = ty; torque[i, 2] = tz


@njit(cache=True, error_model="numpy")
def _keep_facet_contact(i, k, s, tri, feature, pos, radius, meshes, candidates):
    """Deduplication rule of the module docstring for candidate ``s`` of sphere ``i``
    (array index ``i``; its candidates are ``candidates.start[k]:candidates.start[k + 1]``)."""
    if feature == FACE:
        return True
    vertices = meshes.vertices
    triangles = meshes.triangles
    tri_edges = meshes.triangle_edges
    f_tri = candidates.triangle
    if feature <= EDGE_CA:
        edge = tri_edges[tri, feature - EDGE_AB]
        vertex = -1
    else:
        edge = -1
        vertex = triangles[tri, feature - VERTEX_A]
    r2 = radius[i] * radius[i]
    for s2 in range(candidates.start[k], candidates.start[k + 1]):
        if s2 == s:
            continue
        t2 = f_tri[s2]
        q = closest_point_on_triangle(pos[i, 0], pos[i, 1], pos[i, 2], vertices[triangles[t2, 0]],
                                      vertices[triangles[t2, 1]], vertices[triangles[t2, 2]])
        if (q.x - pos[i, 0]) ** 2 + (q.y - pos[i, 1]) ** 2 + (q.z - pos[i, 2]) ** 2 >= r2:
            continue
        f2 = q.feature
        if edge >= 0:
            if tri_edges[t2, 0] == edge or tri_edges[t2, 1] == edge or tri_edges[t2, 2] == edge:
                if f2 == FACE:
                    return False
                if f2 <= EDGE_CA and tri_edges[t2, f2 - EDGE_AB] == edge and t2 < tri:
                    return False
        else:
            if triangles[t2, 0] == vertex or triangles[t2, 1] == vertex or triangles[t2, 2] == vertex:
                if f2 <= EDGE_CA:
                    return False
                if triangles[t2, f2 - VERTEX_A] == vertex and t2 < tri:
                    return False
    return True


@njit(cache=True, error_model="numpy")
def _facet_candidate_active(i, k, s, pos, radius, meshes, candidates):
    vertices = meshes.vertices
    triangles = meshes.triangles
    t = candidates.triangle[s]
    q = closest_point_on_triangle(pos[i, 0], pos[i, 1], pos[i, 2], vertices[triangles[t, 0]],
                                  vertices[triangles[t, 1]], vertices[triangles[t, 2]])
    d2 = (q.x - pos[i, 0]) ** 2 + (q.y - pos[i, 1]) ** 2 + (q.z - pos[i, 2]) ** 2
    if d2 >= radius[i] * radius[i]:
        return False
    return _keep_facet_contact(i, k, s, t, q.feature, pos, radius, meshes, candidates)


@njit(cache=True, error_model="numpy")
def facet_contacts_of(i, k, settings, particles, params, meshes, candidates, resultant, energy):
    """Sphere–triangle contacts of sphere ``i`` (public index ``k``: its candidates are
    ``candidates.start[k]:candidates.start[k + 1]``, in triangle order); closest point on the
    face, an edge or a vertex, deduplicated (module docstring).

    (1) which candidates are in contact; (2) a new contact on a mesh takes over the
    history of a contact on the same mesh that has just ended (a sphere rolling or
    sliding across a shared edge keeps its tangential spring); (3) forces, added in
    candidate order to ``resultant`` (force 3, torque 3 on the sphere), which is
    returned. ``candidates.force`` (force on the sphere, zero if inactive) and
    ``candidates.barycentric`` (weights of the closest point) feed
    :func:`facet_vertex_forces`. ``energy`` (``state.W_*``) += the facets' work on the
    sphere and the contact energy terms of this step.
    """
    law = settings.law
    dt = settings.dt
    pos = particles.pos
    radius = particles.radius
    material = particles.material
    young = params.young
    pair_params = params.pair_params
    vertices = meshes.vertices
    vertex_vel = meshes.vertex_velocity
    triangles = meshes.triangles
    tri_mat = meshes.triangle_material
    tri_mesh = meshes.triangle_mesh
    f_tri = candidates.triangle
    history = candidates.history
    active = candidates.active
    cand_force = candidates.force
    cand_lambda = candidates.barycentric
    sfx, sfy, sfz, stx, sty, stz = resultant
    r = radius[i]
    sphere = sphere_state(particles, i)
    s0 = candidates.start[k]
    s1 = candidates.start[k + 1]
    for s in range(s0, s1):
        active[s] = _facet_candidate_active(i, k, s, pos, radius, meshes, candidates)
    for s in range(s0, s1):
        if not active[s] or np.any(history[s] != 0.0):
            continue
        for s2 in range(s0, s1):
            if not active[s2] and tri_mesh[f_tri[s2]] == tri_mesh[f_tri[s]] and np.any(history[s2] != 0.0):
                history[s, :] = history[s2, :]
                history[s2, :] = 0.0
                break
    for s in range(s0, s1):
        t = f_tri[s]
        h = history[s]
        k_lin = linear_normal_stiffness(young[material[i]], r, young[tri_mat[t]], r)
        if not active[s]:
            release_springs(law, pair_params, material[i], tri_mat[t], k_lin, r, h, energy)
            cand_force[s, :] = 0.0
            continue
        a = vertices[triangles[t, 0]]
        bb = vertices[triangles[t, 1]]
        c = vertices[triangles[t, 2]]
        q = closest_point_on_triangle(pos[i, 0], pos[i, 1], pos[i, 2], a, bb, c)
        dx = q.x - pos[i, 0]
        dy = q.y - pos[i, 1]
        dz = q.z - pos[i, 2]
        dist = np.sqrt(dx * dx + dy * dy + dz * dz)
        overlap = r - dist
        if dist > 0.0:
            nx = dx / dist
            ny = dy / dist
            nz = dz / dist
        else:  # centre on the triangle: use the face normal
            ux = bb[0] - a[0]; uy = bb[1] - a[1]; uz = bb[2] - a[2]
            wx = c[0] - a[0]; wy = c[1] - a[1]; wz = c[2] - a[2]
            nx = uy * wz - uz * wy
            ny = uz * wx - ux * wz
            nz = ux * wy - uy * wx
            norm = np.sqrt(nx * nx + ny * ny + nz * nz)
            nx /= norm
            ny /= norm
            nz /= norm
        la, lb, lc = q.la, q.lb, q.lc
        va = vertex_vel[triangles[t, 0]]
        vb = vertex_vel[triangles[t, 1]]
        vc = vertex_vel[triangles[t, 2]]
        vfx = la * va[0] + lb * vb[0] + lc * vc[0]
        vfy = la * va[1] + lb * vb[1] + lc * vc[1]
        vfz = la * va[2] + lb * vb[2] + lc * vc[2]
        fx, fy, fz, tx, ty, tz = sphere_on_surface(law, dt, pair_params, sphere, tri_mat[t], k_lin,
                                                   ContactGeometry(nx, ny, nz, overlap), vfx, vfy, vfz, h, energy)
        cand_force[s, 0] = fx
        cand_force[s, 1] = fy
        cand_force[s, 2] = fz
        cand_lambda[s, 0] = la
        cand_lambda[s, 1] = lb
        cand_lambda[s, 2] = lc
        sfx += fx
        sfy += fy
        sfz += fz
        stx += tx
        sty += ty
        stz += tz
    return sfx, sfy, sfz, stx, sty, stz


@njit(cache=True, error_model="numpy")
def facet_vertex_forces(meshes, candidates):
    """Force on the facet vertices: −λ_a F per active candidate (serial, fixed order),
    into ``meshes.vertex_force``."""
    vertex_forces_of_rows(meshes.vertex_force, meshes.triangles, candidates.triangle, candidates.barycentric,
                          candidates.force)


@njit(cache=True, error_model="numpy")
def vertex_forces_of_rows(vertex_force, triangles, triangle, barycentric, force):
    """``vertex_force`` = Σ −λ_a F over contact rows (triangle, weights, force on the
    particle), in row order: :func:`facet_vertex_forces` for rows gathered from
    several ranks (de_domain.distributed)."""
    vertex_force[:, :] = 0.0
    for s in range(triangle.size):
        if force[s, 0] == 0.0 and force[s, 1] == 0.0 and force[s, 2] == 0.0:
            continue
        t = triangle[s]
        for a in range(3):
            v = triangles[t, a]
            for d in range(3):
                vertex_force[v, d] -= barycentric[s, a] * force[s, d]
