"""Engine.set_materials: contact parameters change in place, contact history survives."""
import dataclasses

import numpy as np
import pytest

from de_domain import Engine, Material, Particles, PlaneWall


def _sliding_block(friction):
    """A sphere pressed on a floor by gravity and dragged sideways at constant speed."""
    mat = Material(density=2650.0, young=1e7, friction=friction, restitution=0.5)
    p = Particles.from_spheres(np.array([[0.0, 0.0, 0.999e-3]]), np.array([1e-3]), materials=[mat])
    engine = Engine(p, [mat], walls=[PlaneWall((0, 0, 0), (0, 0, 1))], gravity=(0, 0, -9.81), local_damping=0.5)
    p.prescribed[0, 0] = True
    p.prescribed_velocity[0, 0] = 1e-3
    p.blocked[0, 3:] = True
    return engine, mat


def test_friction_changes_in_place_and_history_is_kept():
    engine, mat = _sliding_block(0.5)
    engine.run(4000)
    fn = engine.wall_fn[0, 0]
    ft = np.linalg.norm(engine.wall_history[0, 0, :3])
    assert ft == pytest.approx(0.5 * fn, rel=1e-6)        # sliding at the Coulomb limit
    engine.set_materials([dataclasses.replace(mat, friction=0.8)])
    assert np.linalg.norm(engine.wall_history[0, 0, :3]) == ft   # the spring is still there
    engine.run(4000)
    assert np.linalg.norm(engine.wall_history[0, 0, :3]) == pytest.approx(0.8 * engine.wall_fn[0, 0], rel=1e-6)


def test_mass_or_stiffness_changes_are_refused():
    engine, mat = _sliding_block(0.5)
    with pytest.raises(ValueError, match="density, young or poisson"):
        engine.set_materials([dataclasses.replace(mat, density=1000.0)])
    with pytest.raises(ValueError, match="rolling stiffness"):
        engine.set_materials([dataclasses.replace(mat, rolling_stiffness=1.0)])
    with pytest.raises(ValueError, match="2 materials given, the engine has 1"):
        engine.set_materials([mat, mat])
