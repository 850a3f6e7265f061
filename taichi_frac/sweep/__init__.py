"""Variant sweeps: many takes of one scene on dask.distributed, with their results collected.

``taichi_frac.sweep(...)`` (this package's :func:`sweep`) and ``taichi-frac sweep`` run the
product of varied scene values, or random draws from them, each variant into its own folder
``DIR/<variant id>/`` (cache, stats, fragment-size histogram), and write ``DIR/sweep.json``,
``DIR/sweep.csv`` and the contact sheet ``DIR/sheet.png``. See docs/guide/sweeps.md.

Modules: ``variants`` (specs, product, draws, ids), ``worker`` (one variant on a Dask worker,
which keeps its World between variants), ``results`` (stats, done-ness, CSV/JSON), ``runner``
(the cluster and the client loop), ``sheet`` (the contact sheet through Blender).
"""

from __future__ import annotations


def sweep(scene, vary, output, *, samples: int | None = None, seed: int = 0, overrides=(),
          frames: int | None = None, workers: int | None = None, scheduler: str | None = None,
          arch: str = "cpu", sheet: bool = True, sheet_options: dict | None = None, progress: bool = True,
          log=None):
    """Run variants of a scene on Dask; returns a ``SweepResult`` (records, counts, paths).

    Args:
        scene: path of the scene file (TOML).
        vary: ``KEY=VALUES`` specs, keys as ``--set``'s: ``"ring.fracture.seed=0:32"`` (0..31),
            ``"ring.fracture.crack_count=1,3,5"``, ``"ring.material.tensile_strength=2e6..6e6"``
            (a continuous range: with ``samples`` only). See ``sweep.variants``.
        output: the sweep's folder; each variant writes ``output/<variant id>/``.
        samples: None runs the product of the values; N runs N random draws.
        seed: the random draws' seed (``samples`` only).
        overrides: ``KEY=VALUE`` overrides applied to every variant (``--set``).
        frames: frames per variant (None: the scene's duration).
        workers: local worker processes (None: one per core). Ignored with ``scheduler``.
        scheduler: address of a running Dask scheduler (``tcp://HOST:PORT``); its workers must
            import taichi_frac and see the scene file and ``output`` at the same paths.
        arch: Taichi backend of the workers.
        sheet: render the contact sheet (needs Blender's Python, ``.venv-blender``).
        sheet_options: ``resolution`` ("200x150"), ``samples`` (8), ``columns``,
            ``blender_python`` for the contact sheet.
        progress: show a progress bar (a line per variant when stderr is not a terminal).
        log: callable(str) for status lines (default: stderr).

    Variants already done in ``output`` (same id, same scene file, a cache matching its
    stats) are not run again; an interrupted sweep resumes where it stopped.
    """
    from .runner import sweep as run_sweep

    return run_sweep(scene, vary, output, samples=samples, seed=seed, overrides=overrides, frames=frames,
                     workers=workers, scheduler=scheduler, arch=arch, sheet=sheet, sheet_options=sheet_options,
                     progress=progress, log=log)


__all__ = ["sweep"]
