"""Conservation laws and the energy balance (docs/design.md §2.15)."""
import numpy as np
import pytest


def total_energy(engine):
    e = engine.energy()
    return e["total"]


def run_gas_energy(make_gas, steps):
    # contact time π√(m*/k) ≈ 2.2e-5 s; Δt ≈ 1/80 of it
    engine = make_gas(n_side=10, friction=0.0, restitution=1.0, dt=2.8e-7)
    engine.step()
    e0 = total_energy(engine)
    worst = 0.0
    for _ in range(steps // 100):
        engine.run(100)
        worst = max(worst, abs(total_energy(engine) - e0) / e0)
    n_contacts = len(engine.contacts()["i"])
    return worst, engine, n_contacts


def test_frictionless_elastic_gas_conserves_energy_short(make_gas):
    """1000 spheres, no friction, no damping: |ΔE|/E ≤ 1e-4 (2,000 steps)."""
    worst, engine, _ = run_gas_energy(make_gas, 2000)
    assert engine.neighbors.n_builds > 1
    assert worst <= 1e-4


@pytest.mark.slow
def test_frictionless_elastic_gas_conserves_energy_10000_steps(make_gas):
    worst, _, _ = run_gas_energy(make_gas, 10000)
    assert worst <= 1e-4


def test_energy_balance_closes_with_friction_and_damping(make_gas):
    """Friction, contact damping, local + viscous background damping, gravity and a
    moving wall: |residual| ≤ 1 % of the dissipated total."""
    engine = make_gas(n_side=8, friction=0.5, restitution=0.5, gravity=(0, 0, -9.81), dt=5e-7,
                      local_damping=0.05, viscous_damping=5.0)
    top = engine.walls[5]
    top.velocity = np.array([0.0, 0.0, -0.5])
    engine.run(4000)
    e = engine.energy()
    for key in ("friction", "contact_damping", "background_damping"):
        assert e[key] > 0.0, key
    assert e["work_walls"] != 0.0
    assert abs(e["residual"]) <= 0.01 * e["dissipated"]


def test_linear_momentum_conserved_without_walls_and_gravity(make_gas):
    engine = make_gas(n_side=6, friction=0.5, restitution=0.5, walls=False, spacing=2.1e-3, dt=5e-7)
    p = engine.particles
    momentum0 = (p.mass[:, None] * p.vel).sum(axis=0)
    scale = np.sum(p.mass * np.linalg.norm(p.vel, axis=1))
    engine.run(2000)
    assert len(engine.contacts()["i"]) > 0 or engine.energy()["friction"] > 0
    momentum = (p.mass[:, None] * p.vel).sum(axis=0)
    assert np.all(np.abs(momentum - momentum0) <= 1e-13 * scale)


def test_prescribed_and_blocked_dofs_and_their_work(make_gas):
    """A piston sphere at prescribed velocity pushes a row of spheres; a z-blocked
    sphere ignores gravity; the piston's work closes the energy balance."""
    from de_domain import Engine, Material, Particles

    mat = [Material(young=5e7, friction=0.3, restitution=0.5)]
    pos = [[0, 0, 0], [2.05e-3, 0, 0], [4.1e-3, 0, 0], [0, 5e-3, 0]]
    p = Particles.from_spheres(pos, 1e-3, materials=mat)
    p.prescribed[0, :] = True
    p.prescribed_velocity[0, :3] = (0.2, 0.0, 0.0)
    p.vel[0] = (0.2, 0.0, 0.0)  # v^{-½} consistent with the prescribed motion
    p.blocked[3, 2] = True
    engine = Engine(p, mat, gravity=(0, 0, -9.81), safety_factor=0.05)
    engine.run(4000)
    assert p.vel[0, 0] == 0.2 and np.all(p.angvel[0] == 0.0)
    assert p.pos[3, 2] == 0.0 and p.vel[3, 2] == 0.0
    e = engine.energy()
    assert e["work_boundary"] > 0.0
    assert abs(e["residual"]) <= 0.01 * (e["work_boundary"] + e["dissipated"])
