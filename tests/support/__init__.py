"""Fixtures the test files share (no tests here): the canonical test bodies (``bodies``:
blocks, spheres, a torus, chips, heaps; ``fracture_ring``: the struck ring of the fracture
controls and the jittered block of the stress tests), the event-driven rigid-drop reference
(``rigid_drop``), Blender runners and piece helpers. The benchmark report (``benchmarks/``)
uses the same bodies, so both describe the same set-ups."""
