"""Shared test set-up: one Taichi runtime per session (CPU backend, offline cache)."""

import os

import pytest

os.environ.setdefault("TI_LOG_LEVEL", "warn")

from taichi_frac import runtime  # noqa: E402

runtime.init("cpu")


@pytest.fixture(scope="session")
def ti_cpu():
    """Taichi initialised on the CPU (done at import; the fixture documents the dependency)."""
    return runtime.init("cpu")


@pytest.fixture(scope="session")
def scene_world():
    """One World big enough for every scene of the paper, shared by the tests that run
    whole scenes (end to end, the run command, the real caches in Blender). Each new
    World compiles the dynamics kernels again for its own fields (~14 s on 2 cores with an
    empty offline cache); a Simulation given this one clears it first."""
    from taichi_frac.dynamics import World, WorldCapacity

    return World(WorldCapacity(max_bodies=4096, max_boundary_particles=200_000, max_contacts=400_000,
                               max_static_boxes=8))


@pytest.fixture(scope="module")
def box():
    """The textured box body of the piece-geometry and crack-fit tests
    (``support.pieces.box_body``): (BodyModel, PrepareReport, trimesh surface)."""
    from support.pieces import box_body

    return box_body()
