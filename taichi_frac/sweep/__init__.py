"""Variant sweeps: many takes of one scene on dask.distributed, with their results collected.

``taichi_frac.sweep.sweep(...)`` and ``taichi-frac sweep`` run the
product of varied scene values, or random draws from them, each variant into its own folder
``DIR/<variant id>/`` (cache, stats, fragment-size histogram), and write ``DIR/sweep.json``,
``DIR/sweep.csv`` and the contact sheet ``DIR/sheet.png``. See docs/guide/sweeps.md.

Modules: ``variants`` (specs, product, draws, ids), ``worker`` (one variant on a Dask worker,
which keeps its World between variants), ``results`` (stats, done-ness, CSV/JSON), ``runner``
(the cluster and the client loop), ``sheet`` (the contact sheet through Blender).
"""

from __future__ import annotations


from .runner import SweepResult, sweep

__all__ = ["SweepResult", "sweep"]
