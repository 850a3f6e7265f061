"""``surfaces.solid.difference``: a solid less many cutters, one at a time where the cutters
hold more triangles than the solid, else in one batch; checked against volumes computed by
hand and the library's own batch difference."""

import manifold3d as m3
import numpy as np
import pytest

from taichi_frac.surfaces.solid import difference


def test_slabs_through_a_cube_leave_the_gaps_between_them():
    """Five slabs 0.02 thick across a unit cube, reaching past it (more triangles than the
    cube: taken away one at a time): six blocks, of the widths between the slabs."""
    planes = np.array([0.1, 0.3, 0.45, 0.7, 0.9])
    thickness = 0.02
    slabs = [m3.Manifold.cube((thickness, 2.0, 2.0)).translate((x - thickness / 2, -0.5, -0.5)) for x in planes]
    cube = m3.Manifold.cube((1.0, 1.0, 1.0))
    assert sum(slab.num_tri() for slab in slabs) > cube.num_tri()
    cut = difference(cube, slabs)
    edges = np.concatenate([[0.0], np.ravel(np.column_stack([planes - thickness / 2, planes + thickness / 2])), [1.0]])
    widths = edges[1::2] - edges[0::2]
    assert cut.volume() == pytest.approx(1.0 - len(planes) * thickness, abs=1e-12)
    blocks = sorted(cut.decompose(), key=lambda block: block.bounding_box()[0])
    np.testing.assert_allclose([block.volume() for block in blocks], widths, atol=1e-12)


def test_many_cutters_and_few_give_the_batch_difference():
    """Twenty disjoint balls inside a cube (cutters with far more triangles: one at a time),
    and two small cubes out of a fine ball (in one batch): the volume left is the solid's
    less each cutter's, as the library's batch difference gives it."""
    rng = np.random.default_rng(7)
    centres = np.array([(x, y, z) for x in (0.2, 0.4, 0.6, 0.8) for y in (0.25, 0.75) for z in (0.3, 0.7)])[:20]
    balls = [m3.Manifold.sphere(0.08 * rng.uniform(0.5, 1.0), 24).translate(tuple(c)) for c in centres]
    cube = m3.Manifold.cube((1.0, 1.0, 1.0))
    holed = difference(cube, balls)
    expected = 1.0 - sum(ball.volume() for ball in balls)
    assert holed.volume() == pytest.approx(expected, rel=1e-12)
    assert holed.volume() == pytest.approx(m3.Manifold.batch_boolean([cube, *balls], m3.OpType.Subtract).volume(),
                                           rel=1e-12)
    ball = m3.Manifold.sphere(1.0, 96)
    cubes = [m3.Manifold.cube((0.2, 0.2, 0.2)).translate((x, -0.1, -0.1)) for x in (-0.5, 0.3)]
    assert sum(c.num_tri() for c in cubes) <= ball.num_tri()
    assert difference(ball, cubes).volume() == pytest.approx(ball.volume() - 2 * 0.2**3, rel=1e-12)
    assert difference(ball, []) is ball
