"""A cubical box of six frictionless rigid walls around a specimen, and the stresses on it
(``cosim elastic`` and the ``triaxial`` kind). Wall order: x = 0, x = L_x, y = 0, y = L_y,
bottom, top; the walls at x = L_x, y = L_y and the top are the ones that move."""
from __future__ import annotations

import numpy as np


def box_walls(lx, ly, lz, material):
    """Six frictionless rigid walls around [0, lx] × [0, ly] × [0, lz]: x0, x1, y0, y1, bottom, top."""
    from de_domain import PlaneWall
    corner = (lx, ly, lz)
    walls = []
    for axis in range(3):
        normal = np.eye(3)[axis]
        walls += [PlaneWall(np.zeros(3), normal, material), PlaneWall(normal * corner[axis], -normal, material)]
    return walls


def wall_stresses(engine):
    """(σ_xx, σ_yy, σ_zz) on the walls x = L_x, y = L_y, z = L_z (compression > 0, Pa)."""
    w = engine.walls
    lx, ly, lz = w[1].point[0] - w[0].point[0], w[3].point[1] - w[2].point[1], w[5].point[2] - w[4].point[2]
    return np.array([w[1].force[0] / (ly * lz), w[3].force[1] / (lx * lz), w[5].force[2] / (lx * ly)])


def box_lengths(engine):
    w = engine.walls
    return np.array([w[1].point[0] - w[0].point[0], w[3].point[1] - w[2].point[1], w[5].point[2] - w[4].point[2]])
