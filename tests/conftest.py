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
