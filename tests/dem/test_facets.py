"""Sphere–facet contacts: one contact at a shared edge/vertex, rest force = weight,
barycentric vertex forces and impulses (docs/design.md §2.10, §5.1)."""
import numpy as np
import pytest

from de_domain import Engine, FacetMesh, Material, Particles

R = 1e-3


def square_two_triangles(L=4e-3):
    """Square [0, L]² at z = 0, split along the diagonal (0,0)–(L,L)."""
    v = [[0, 0, 0], [L, 0, 0], [0, L, 0], [L, L, 0]]
    return FacetMesh(v, [[0, 1, 3], [0, 3, 2]])


def square_fan(L=4e-3):
    """Square [0, L]² at z = 0 as four triangles sharing the centre vertex 4."""
    v = [[0, 0, 0], [L, 0, 0], [L, L, 0], [0, L, 0], [L / 2, L / 2, 0]]
    return FacetMesh(v, [[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]])


def ridge(L=4e-3, angle_deg=20.0):
    """Two planes meeting at a convex ridge along y at x = L/2 (roof shape)."""
    h = np.tan(np.radians(angle_deg)) * L / 2
    v = [[0, 0, 0], [L / 2, 0, h], [L, 0, 0], [0, L, 0], [L / 2, L, h], [L, L, 0]]
    return FacetMesh(v, [[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4]])


def settle(mesh, x, y, z0, steps=6000):
    mat = [Material(young=5e7, friction=0.5, restitution=0.2)]
    p = Particles.from_spheres([[x, y, z0]], R, materials=mat)
    engine = Engine(p, mat, facets=[mesh], local_damping=0.3)
    counts = set()
    for _ in range(steps):
        engine.step()
        counts.add(len(engine.contacts()["facet_particle"]))
    return engine, counts


@pytest.mark.parametrize("mesh_factory, where", [
    (square_two_triangles, (2e-3, 2e-3)),  # on the shared diagonal edge
    (square_two_triangles, (1.0e-3, 1.0e-3)),  # on the shared edge, elsewhere
    (square_fan, (2e-3, 2e-3)),  # on the shared centre vertex (4 triangles)
    (ridge, (2e-3, 2e-3)),  # on a convex ridge
])
def test_one_contact_at_shared_feature_and_rest_force_equals_weight(mesh_factory, where):
    mesh = mesh_factory()
    top = mesh.vertices[:, 2].max()
    engine, counts = settle(mesh, where[0], where[1], top + R + 1e-5)
    p = engine.particles
    weight = p.mass[0] * 9.81
    assert counts <= {0, 1}  # never two contacts
    c = engine.contacts()
    assert len(c["facet_particle"]) == 1
    assert c["facet_force"][0] == pytest.approx([0.0, 0.0, weight], rel=1e-6, abs=1e-9 * weight)
    assert mesh.force == pytest.approx([0.0, 0.0, -weight], rel=1e-6, abs=1e-9 * weight)
    assert mesh.vertex_force.sum(axis=0) == pytest.approx(mesh.force, rel=1e-12, abs=1e-15)


def test_vertex_forces_split_barycentrically_and_impulse_accumulates():
    mesh = square_two_triangles()
    engine, _ = settle(mesh, 3e-3, 1e-3, R + 1e-5, steps=3000)
    lam = engine.contacts()["facet_lambda"][0]
    tri = mesh.triangles[engine.contacts()["facet_triangle"][0]]
    f = engine.contacts()["facet_force"][0]
    expected = np.zeros_like(mesh.vertex_force)
    for a in range(3):
        expected[tri[a]] -= lam[a] * f
    assert mesh.vertex_force == pytest.approx(expected, rel=1e-12, abs=1e-18)
    mesh.reset_impulse()
    engine.run(10)
    assert mesh.vertex_impulse.sum(axis=0) == pytest.approx(10 * engine.dt * mesh.force, rel=1e-6)


def test_moving_facets_driven_from_outside_do_tracked_work():
    """A facet floor pushed up through set_vertex_state: the work shows in the balance."""
    mesh = square_two_triangles(L=8e-3)
    mat = [Material(young=5e7, friction=0.5, restitution=0.5)]
    p = Particles.from_spheres([[4e-3, 4e-3, R]], R, materials=mat)
    engine = Engine(p, mat, facets=[mesh], gravity=(0, 0, -9.81), safety_factor=0.05)
    v = np.array([0.0, 0.0, 0.05])
    for _ in range(18000):
        mesh.set_vertex_state(mesh.vertices, np.tile(v, (4, 1)))
        engine.step()
    e = engine.energy()
    assert e["work_walls"] > 0
    assert abs(e["residual"]) <= 0.01 * (e["work_walls"] + e["dissipated"])
    assert p.vel[0, 2] == pytest.approx(0.05, rel=0.02)


def test_tangential_spring_carried_across_a_shared_edge():
    """A sphere held by friction on a tilted floor, on the shared diagonal edge: its
    elastic creep moves the contact from triangle 0 (edge) to triangle 1 (face); the
    new contact inherits the tangential spring, so the friction force is continuous
    across the switch (it would drop to ≈ k_t v Δt ≈ 0 if the spring restarted)."""
    mesh = square_two_triangles(L=8e-3)
    mat = [Material(young=5e7, friction=0.5, restitution=0.2)]
    p = Particles.from_spheres([[4e-3 + 2e-10, 4e-3 - 2e-10, R]], R, materials=mat)  # just inside triangle 0
    p.blocked[0, 3:] = True
    theta = np.radians(15.0)
    downhill = np.array([-1.0, 1.0, 0.0]) / np.sqrt(2.0)
    gravity = 9.81 * (np.sin(theta) * downhill - np.cos(theta) * np.array([0, 0, 1.0]))
    engine = Engine(p, mat, facets=[mesh], gravity=gravity, safety_factor=0.02)  # k_t v Δt ≪ |F_t|
    p.pos[0, 2] = R - p.mass[0] * 9.81 * np.cos(theta) / (2 * 5e7 * R)
    seen, friction = [], []
    for _ in range(20000):
        engine.step()
        c = engine.contacts()
        assert len(c["facet_particle"]) == 1
        seen.append(int(c["facet_triangle"][0]))
        friction.append(np.linalg.norm(c["facet_force"][0][:2]))
        if seen[-1] != seen[0]:
            break
    assert seen[0] == 0 and seen[-1] == 1
    assert friction[-2] > 0.1 * p.mass[0] * 9.81 * np.sin(theta)
    assert friction[-1] == pytest.approx(friction[-2], rel=0.25)
