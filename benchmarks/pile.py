"""The loose fragment pile of ``taichi-frac bench dynamics`` (ours and pybullet's): one
layout, numpy only."""

from __future__ import annotations

import math

import numpy as np

#: The pile's fragment: an icosphere (subdivisions 1) of this radius [m] and density [kg/m^3].
FRAGMENT_RADIUS = 0.02
FRAGMENT_DENSITY = 2400.0

#: The four static walls of the 0.44 m box on the ground: (centre (3,) [m], half extents (3,) [m]).
WALLS = tuple((tuple(c), h) for sign in (-1, 1) for c, h in (
    ((sign * 0.22, 0.0, 0.3), (0.02, 0.24, 0.3)),
    ((0.0, sign * 0.22, 0.3), (0.24, 0.02, 0.3)),
))


def layout(count: int, seed: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """``count`` fragments on a loose cube lattice of 0.05 m pitch centred over the origin,
    jittered by 3 mm, with random angular velocities (2 rad/s per axis): positions (count,3)
    [m] and angular velocities (count,3) [rad/s], drawn in that order per fragment."""
    side = math.ceil(count ** (1 / 3))
    rng = np.random.default_rng(seed)
    cells = np.stack(np.meshgrid(*(np.arange(side),) * 3, indexing="ij"), -1).reshape(-1, 3)[:count]
    positions, spins = np.zeros((len(cells), 3)), np.zeros((len(cells), 3))
    for k, c in enumerate(cells):
        positions[k] = (c - [side / 2 - 0.5, side / 2 - 0.5, -0.5]) * 0.05 + rng.normal(0, 0.003, 3)
        spins[k] = rng.normal(0, 2.0, 3)
    return positions, spins
