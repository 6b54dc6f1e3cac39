"""Rigid-body rotation by NO_SQUISH (de_domain.rigid) against closed forms and an independent
solution of Euler's equations."""
import math

import numpy as np
import pytest
from numba import njit
from scipy.integrate import solve_ivp

from de_domain.rigid import (
    LANES,
    N_W,
    W_INERTIA,
    W_MOMENTUM,
    W_OMEGA,
    W_QUAT,
    body_momentum,
    conjugate_momentum,
    free_rotation,
    leapfrog_lanes,
    quat_multiply,
    rotational_energy,
    rotational_leapfrog,
    sin_cos,
    to_body,
    to_space,
)

INERTIA = np.array([1.0, 2.0, 3.0])  # an asymmetric body, I1 < I2 < I3


def rotation_matrix(q):
    q0, q1, q2, q3 = q
    return np.array([[1 - 2 * (q2 * q2 + q3 * q3), 2 * (q1 * q2 - q0 * q3), 2 * (q1 * q3 + q0 * q2)],
                     [2 * (q1 * q2 + q0 * q3), 1 - 2 * (q1 * q1 + q3 * q3), 2 * (q2 * q3 - q0 * q1)],
                     [2 * (q1 * q3 - q0 * q2), 2 * (q2 * q3 + q0 * q1), 1 - 2 * (q1 * q1 + q2 * q2)]])


def random_quaternion(rng):
    q = rng.normal(size=4)
    return tuple(q / np.linalg.norm(q))


def test_quaternion_rotation_is_the_rotation_matrix():
    rng = np.random.default_rng(1)
    for _ in range(20):
        q = random_quaternion(rng)
        x = rng.normal(size=3)
        assert np.allclose(to_space(q, *x), rotation_matrix(q) @ x, rtol=0, atol=1e-14)
        assert np.allclose(to_body(q, *to_space(q, *x)), x, rtol=0, atol=1e-14)
        # composition: rotating by a ⊗ b is rotating by b, then by a
        b = random_quaternion(rng)
        assert np.allclose(to_space(quat_multiply(q, b), *x), to_space(q, *to_space(b, *x)), atol=1e-14)


def test_conjugate_momentum_round_trip():
    rng = np.random.default_rng(2)
    q = random_quaternion(rng)
    big_l = rng.normal(size=3)
    p = conjugate_momentum(q, *big_l)
    assert np.allclose(to_space(q, *body_momentum(q, p)), big_l, atol=1e-14)


@njit
def _free_run(q, p, inertia, dt, steps, every):
    """Energies, space-frame angular momenta and body-frame momenta every ``every`` steps."""
    n = steps // every + 1
    energy = np.empty(n)
    momentum = np.empty((n, 3))
    body = np.empty((n, 3))
    for k in range(steps + 1):
        if k % every == 0:
            row = k // every
            energy[row] = rotational_energy(q, p, inertia)
            b = body_momentum(q, p)
            s = to_space(q, b[0], b[1], b[2])
            for d in range(3):
                momentum[row, d] = s[d]
                body[row, d] = b[d]
        if k < steps:
            q, p = free_rotation(q, p, inertia, dt)
    return energy, momentum, body


def test_torque_free_body_keeps_energy_and_angular_momentum():
    """1e5 steps of an asymmetric body turning about all three axes (|ω| Δt ≈ 3e-4): the energy
    to 1e-6 (it oscillates, no drift: symplectic) and the space-frame angular momentum to
    round-off (each sub-rotation keeps it exactly)."""
    rng = np.random.default_rng(3)
    q = random_quaternion(rng)
    big_l = np.array([0.3, -0.7, 0.5])
    dt = 3e-4 / np.linalg.norm(big_l / INERTIA)
    energy, momentum, _ = _free_run(q, conjugate_momentum(q, *big_l), INERTIA, dt, 100_000, 100)
    assert np.max(np.abs(energy / energy[0] - 1.0)) < 1e-6
    assert np.max(np.abs(momentum - big_l)) < 1e-10 * np.linalg.norm(big_l)
    # no drift: the last tenth's mean error is no larger than the first tenth's spread
    tenth = energy.size // 10
    assert abs(np.mean(energy[-tenth:]) - np.mean(energy[:tenth])) < 5e-7 * energy[0]


def euler_reference(big_l_body, inertia, times):
    """Body-frame angular momentum from Euler's equations dL_b/dt = L_b × ω, ω = L_b/I
    (an independent solution, scipy's DOP853 at rtol 1e-12)."""
    def rhs(_, y):
        w = y / inertia
        return np.cross(y, w)
    sol = solve_ivp(rhs, (times[0], times[-1]), big_l_body, method="DOP853", t_eval=times, rtol=1e-12, atol=1e-14)
    return sol.y.T


def test_intermediate_axis_flips_as_eulers_equations_say():
    """Spin about the intermediate axis (I2) with a 1e-3 perturbation: the body flips (L_b,2
    changes sign, the Dzhanibekov effect) and NO_SQUISH follows the independent solution of
    Euler's equations through the flips; about the largest and the smallest axis it does not flip."""
    q = (1.0, 0.0, 0.0, 0.0)
    big_l = np.array([1e-3, 2.0, 1e-3])  # body = space frame at t = 0
    omega = np.linalg.norm(big_l / INERTIA)
    dt = 2e-4 / omega
    steps, every = 500_000, 500  # t = 100/ω: about four flips
    energy, momentum, body = _free_run(q, conjugate_momentum(q, *big_l), INERTIA, dt, steps, every)
    signs = np.sign(body[:, 1])
    flips = np.count_nonzero(signs[1:] != signs[:-1])
    assert flips >= 2
    reference = euler_reference(big_l, INERTIA, np.arange(body.shape[0]) * every * dt)
    assert np.max(np.abs(body - reference)) < 1e-5 * np.linalg.norm(big_l)
    assert np.max(np.abs(energy / energy[0] - 1.0)) < 1e-6
    for axis in (0, 2):  # stable axes
        big_l = np.full(3, 1e-3)
        big_l[axis] = 2.0
        _, _, body = _free_run(q, conjugate_momentum(q, *big_l), INERTIA, dt, steps // 4, every)
        assert np.all(np.sign(body[:, axis]) == 1.0)


def test_fixed_axis_rotation_is_the_scalar_leapfrog():
    """A constant torque along a principal axis: the body turns about that axis, and the angle
    after each step is the spheres' leapfrog ω^{n+½} = ω^{n−½} + τΔt/I, θ^{n+1} = θⁿ + ω^{n+½}Δt."""
    rng = np.random.default_rng(4)
    q0 = random_quaternion(rng)
    axis = 1
    body_axis = np.eye(3)[axis]
    torque = 0.7 * np.array(to_space(q0, *body_axis))
    dt = 1e-3
    q, big_l = q0, (0.0, 0.0, 0.0)
    theta, w = 0.0, 0.0
    for _ in range(2000):
        q, big_l, omega = rotational_leapfrog(q, big_l, torque, INERTIA, dt)
        w += 0.7 * dt / INERTIA[axis]
        theta += w * dt
        turn = (math.cos(theta / 2), *(math.sin(theta / 2) * body_axis))
        assert np.allclose(q, quat_multiply(q0, turn), atol=1e-12)
        assert np.allclose(omega, w * np.array(to_space(q0, *body_axis)), rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("dt_scale", [1.0, 0.5])
def test_energy_error_is_second_order(dt_scale):
    """Halving Δt quarters the energy error's amplitude (a second-order scheme)."""
    q = (1.0, 0.0, 0.0, 0.0)
    big_l = np.array([0.5, 1.0, 0.8])
    dt = 0.05 * dt_scale
    steps = int(200 / dt_scale)
    energy, _, _ = _free_run(q, conjugate_momentum(q, *big_l), INERTIA, dt, steps, 1)
    amplitude = np.max(np.abs(energy / energy[0] - 1.0))
    reference, _, _ = _free_run(q, conjugate_momentum(q, *big_l), INERTIA, dt / 2, 2 * steps, 1)
    assert amplitude / np.max(np.abs(reference / reference[0] - 1.0)) == pytest.approx(4.0, rel=0.15)


def test_sin_cos_is_the_math_librarys_within_two_ulp():
    """The rotation's own sine and cosine (no library call, so the loops over bodies vectorise)
    against the math library: within 2 ulp where the value is not near 0, within 2e-16 absolutely
    everywhere, over the angles a step turns (|z| ≪ 1), the quadrants and far beyond (|z| < 1e5)."""
    rng = np.random.default_rng(5)
    angles = np.concatenate([rng.uniform(-1e-3, 1e-3, 500), rng.uniform(-4.0, 4.0, 2000),
                             rng.uniform(-1e5, 1e5, 2000), 0.5 * math.pi * np.arange(-8, 9),
                             [0.0, 1e-300, math.pi / 4, -3 * math.pi / 4]])
    for z in angles:
        c, s = sin_cos(z)
        for ours, exact in ((c, math.cos(z)), (s, math.sin(z))):
            assert abs(ours - exact) <= 2e-16 or abs(ours - exact) <= 2 * math.ulp(exact), z


def test_a_block_of_bodies_turns_as_each_body_alone():
    """leapfrog_lanes on a block of bodies (the clumps' step: the compiler computes four lanes at a
    time, then the remainder one by one) gives each body the bits rotational_leapfrog gives it
    alone, in whichever lane it sits and whatever the block's size: the DEM's bit-identity for any
    thread and rank count rests on this."""
    rng = np.random.default_rng(6)
    bodies = [(random_quaternion(rng), tuple(rng.normal(size=3)), tuple(0.5 + rng.random(3))) for _ in range(LANES)]
    dt = 1e-3
    alone = [rotational_leapfrog(q, big_l, (0.0, 0.0, 0.0), inertia, dt) for q, big_l, inertia in bodies]
    for count, shift in ((LANES, 0), (7, 0), (7, 3), (LANES - 5, 5)):
        w = np.zeros(N_W * LANES)
        for lane in range(count):
            q, big_l, inertia = bodies[(lane + shift) % LANES]
            w[[(W_QUAT + j) * LANES + lane for j in range(4)]] = q
            w[[(W_MOMENTUM + j) * LANES + lane for j in range(3)]] = big_l
            w[[(W_INERTIA + j) * LANES + lane for j in range(3)]] = inertia
        leapfrog_lanes(w, count, dt)
        for lane in range(count):
            q, big_l, omega = alone[(lane + shift) % LANES]
            assert tuple(w[[(W_QUAT + j) * LANES + lane for j in range(4)]]) == q
            assert tuple(w[[(W_MOMENTUM + j) * LANES + lane for j in range(3)]]) == big_l
            assert tuple(w[[(W_OMEGA + j) * LANES + lane for j in range(3)]]) == omega
