"""Mass scaling of a material (Material.inertia_scale, docs/design.md §4.9): the inertia
scaled, the weight not — a stiff structure's step raised without changing what it carries."""

import numpy as np
import pytest
from mpi4py import MPI

from fe_domain.boundary import BodyForce, Fixed, GeostaticStress, LocalNonViscousDamping, Material
from fe_domain.explicit import ExplicitSolid
from fe_domain.mesh import load_geo

E, NU, RHO, G, S = 1e6, 0.3, 1600.0, 9.81, 100.0
GRAVITY = (0.0, 0.0, -G)
ROLLERS = [Fixed("x0", (0,)), Fixed("x1", (0,)), Fixed("y0", (1,)), Fixed("y1", (1,)), Fixed("bottom", (2,))]


def column(scale, loads=(), damping=None):
    """The unit cube (meshes/block.geo) between rollers on its sides and base."""
    return ExplicitSolid(load_geo("block", 0.25, MPI.COMM_SELF), Material(E=E, nu=NU, rho=RHO, inertia_scale=scale),
                         boundary_conditions=ROLLERS, loads=list(loads), damping=damping,
                         formulation="displacement")


def test_the_inertia_scale_scales_mass_and_step_but_not_weight():
    """S = 100: the lumped mass 100× and the critical step 10× (c_p / √S); the weight on the
    base and the geostatic stress are ρ's, so a column given its σ0 stays at rest."""
    plain, scaled = column(1.0), column(S, [BodyForce(GRAVITY), GeostaticStress(GRAVITY, (0.0, 0.0, 1.0), 0.5,
                                                                                  ("solid",))])
    assert scaled.mass == pytest.approx(S * plain.mass, rel=1e-12)
    assert scaled.dt_critical == pytest.approx(np.sqrt(S) * plain.dt_critical, rel=1e-12)
    assert Material(E=E, nu=NU, rho=RHO, inertia_scale=S).p_wave_speed == pytest.approx(
        Material(E=E, nu=NU, rho=RHO).p_wave_speed / np.sqrt(S), rel=1e-12)
    scaled.run(200)
    assert np.abs(scaled.displacement).max() < 1e-9 * RHO * G / E
    assert scaled.reaction("bottom")[2] == pytest.approx(RHO * G * 1.0, rel=1e-12)


def test_a_mass_scaled_column_settles_as_far_under_its_weight():
    """Loaded by its weight from zero stress and brought to rest (local damping), the column
    settles the same with S = 100 as without: the static answer does not see the inertia."""
    settled = []
    for scale in (1.0, S):
        solid = column(scale, [BodyForce(GRAVITY)], LocalNonViscousDamping(0.7))
        solid.run(3000)
        assert np.abs(solid.velocity).max() < 1e-6 * np.abs(solid.displacement).max() / solid.dt
        settled.append(solid.displacement[:, 2].min())
    assert settled[1] == pytest.approx(settled[0], rel=1e-6)


def test_an_inertia_scale_below_one_is_refused():
    with pytest.raises(ValueError, match="inertia_scale"):
        Material(E=E, nu=NU, rho=RHO, inertia_scale=0.5)
