"""One place that initialises Taichi.

Every module that launches kernels calls :func:`init` first; it is a no-op after the first
call. Nothing else in the package (or in the tests) may call ``ti.init`` or ``ti.reset``:
a second ``ti.init`` throws away every field and compiled kernel.
"""

from __future__ import annotations

import os
from pathlib import Path

import taichi as ti

_ARCHES = {"cpu": "cpu", "cuda": "cuda", "vulkan": "vulkan", "gpu": "gpu", "metal": "metal"}
_initialised_arch: str | None = None


def cache_dir() -> Path:
    """Folder for taichi-frac's on-disk caches (Taichi's offline kernel cache, meshes)."""
    root = os.environ.get("TAICHI_FRAC_CACHE") or os.path.join(
        os.environ.get("XDG_CACHE_HOME", os.path.expanduser("~/.cache")), "taichi-frac"
    )
    path = Path(root)
    path.mkdir(parents=True, exist_ok=True)
    return path


class ArchError(RuntimeError):
    """Another Taichi arch was asked for than the one this process already runs on."""


def init(arch: str | None = None, *, debug: bool = False) -> str:
    """Initialise Taichi once per process and return the arch in use.

    ``arch`` is one of cpu, cuda, vulkan, metal, gpu; None takes the arch already in use,
    or cpu. Taichi runs on one arch per process, so asking for another once a kernel has
    run is an error (rather than silently keeping the first arch: a run asked for cuda
    would get the CPU when its models were prepared first). Fields use float32 by default
    (``default_fp``); accuracy-critical fracture kernels declare float64 explicitly.
    Compiled kernels are kept in Taichi's offline cache under :func:`cache_dir`, so a second
    process does not recompile them.
    """
    global _initialised_arch
    if _initialised_arch is not None:
        if arch is not None and arch != _initialised_arch:
            raise ArchError(f"Taichi is already running on arch {_initialised_arch!r} in this process, so "
                            f"arch {arch!r} cannot be used: ask for {_initialised_arch!r} (a scene's "
                            f"[simulation] arch, Simulation(..., arch=...)), or choose the arch before "
                            f"anything runs a kernel (e.g. taichi-frac run --arch {arch} in a new process)")
        return _initialised_arch
    arch = "cpu" if arch is None else arch
    if arch not in _ARCHES:
        raise ValueError(f"unknown Taichi arch {arch!r}: use one of {', '.join(sorted(_ARCHES))}")
    ti.init(
        arch=getattr(ti, _ARCHES[arch]),
        default_fp=ti.f32,
        default_ip=ti.i32,
        offline_cache=True,
        offline_cache_file_path=str(cache_dir() / "ticache"),
        debug=debug,
        log_level=ti.WARN,
    )
    _initialised_arch = arch
    global SERIAL_SMALL_LOOPS
    SERIAL_SMALL_LOOPS = arch == "cpu"
    return arch


# Loops over bodies, contacts and buckets run serially on the CPU backend: there a
# parallel-for task costs 25-60 us to dispatch (measured, Taichi 1.7.4, 2 cores), more
# than a serial pass over a few thousand items. Read by kernels at compile time
# (``ti.loop_config(serialize=runtime.SERIAL_SMALL_LOOPS)``), set by init().
SERIAL_SMALL_LOOPS = True


def is_initialised() -> bool:
    return _initialised_arch is not None
