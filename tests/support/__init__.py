"""Fixtures the test files share (no tests here); the set-ups the benchmark report also uses
live in the package (``taichi_frac.bench.bodies``, ``taichi_frac.bench.fracture_ring``)."""
