"""One place that initialises Taichi, and ends it.

Every module that launches kernels calls :func:`init` first; it is a no-op after the first
call. :func:`finish` ends the runtime at a process's last use (it writes the offline kernel
cache). Nothing else in the package (or in the tests) may call ``ti.init`` or ``ti.reset``:
a second ``ti.init`` throws away every field and compiled kernel.
"""

from __future__ import annotations

import contextlib
import functools
import linecache
import os
import sys
from pathlib import Path

# Taichi prints its banner on stdout at import and at ti.init; stdout carries a command's
# result (``info --json``), so the banner goes to stderr. Taichi takes a replaced stdout
# for a notebook's and then wraps every kernel call to flush in-kernel prints to it (and
# says so): none of our kernels prints, so that buffer is turned off.
os.environ.setdefault("TI_ENABLE_PYBUF", "0")
with contextlib.redirect_stdout(sys.stderr):
    import taichi as ti


def _cheap_class_check() -> None:
    """Taichi 1.7 asks at each ``ti.func`` / ``ti.kernel`` decoration whether it stands in a
    class body by reading the source line of a frame that, for a function defined in a
    module, is the import machinery's frozen frame: ``inspect`` finds no source for it only
    after walking every loaded module to look for its file, about 1.3 ms a decoration, 0.23 s
    of every run's start (174 decorations among 1,500 modules). The same check reads that
    line from the line cache, which answers the frozen frame at once; the answer is the same
    (each of a 13-rings run's 174 decorations compared). Our modules import Taichi through
    this module (``from ..runtime import ti``), so the check is in place before they
    decorate. TAICHI_FRAC_STOCK_TAICHI=1 keeps Taichi's own."""
    from taichi.lang import kernel_impl

    patterns = getattr(kernel_impl, "_KERNEL_CLASS_STACKFRAME_STMT_RES", None)
    if os.environ.get("TAICHI_FRAC_STOCK_TAICHI") == "1" or patterns is None \
            or not hasattr(kernel_impl, "_inside_class"):
        return

    def _inside_class(level_of_class_stackframe):
        try:
            frame = sys._getframe(level_of_class_stackframe)
            first = linecache.getline(frame.f_code.co_filename, frame.f_lineno).strip()
        except ValueError:  # (no frame that deep)
            return False
        return any(pattern.match(first) for pattern in patterns)

    kernel_impl._inside_class = _inside_class


_cheap_class_check()

_ARCHES = {"cpu": "cpu", "cuda": "cuda", "vulkan": "vulkan", "gpu": "gpu", "metal": "metal"}
_DEVICE_NAMES = {"cuda": "CUDA", "vulkan": "Vulkan", "metal": "Metal", "gpu": "GPU"}
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
    """An arch that cannot be had: not on this machine, or another than the one this
    process already runs on."""


def _plain_source_positions() -> None:
    """Taichi 1.7 turns each kernel's Python source into its IR in every new process, even
    when its offline cache holds the compiled kernel, and for every AST node it renders a
    caret diagram of the node's source (textwrap) into the statement's debug info: about
    half of that front end's time. The debug info keeps the file, line, function and source
    line, which is what Taichi's error messages print first; only the carets go. Set
    TAICHI_FRAC_STOCK_TAICHI=1 to keep Taichi's front end as shipped (the kernels compile
    the same either way)."""
    from taichi.lang.ast import ast_transformer_utils

    context = ast_transformer_utils.ASTTransformerContext
    if os.environ.get("TAICHI_FRAC_STOCK_TAICHI") == "1" or not hasattr(context, "get_pos_info"):
        return

    def get_pos_info(self, node):
        return (f'File "{self.file}", line {node.lineno + self.lineno_offset}, in {self.func.func.__name__}:\n'
                f"{self.src[node.lineno - 1]}\n")

    context.get_pos_info = get_pos_info
    # Each call site of a ti.func reads the function's source again (inspect walks every
    # loaded module to find its file, then tokenizes it): a function's source does not
    # change while the process runs, so it is read once.
    from taichi.lang import kernel_impl

    for name in ("getsourcefile", "getsourcelines"):
        found = getattr(kernel_impl, name, None)
        if found is not None and not hasattr(found, "cache_info"):
            setattr(kernel_impl, name, functools.lru_cache(maxsize=None)(found))
    # ... and re-wraps every source line and dedents the whole (textwrap) before parsing it:
    # the same lines give the same text, kept.
    import textwrap
    import types

    if getattr(kernel_impl, "textwrap", None) is textwrap:
        kernel_impl.textwrap = types.SimpleNamespace(fill=functools.lru_cache(maxsize=None)(textwrap.fill),
                                                     dedent=functools.lru_cache(maxsize=None)(textwrap.dedent))


def _arches_of(name: str) -> set:
    """Taichi's arch values that satisfy ``name`` (cpu: x64 or arm64; gpu: any GPU)."""
    if name == "cpu":
        return {ti.x64, ti.arm64}
    if name == "gpu":
        return set(_gpu_arches())
    return {getattr(ti, _ARCHES[name])}


def _gpu_arches() -> list:
    """What "gpu" tries, in order. Not Taichi's own ``ti.gpu`` list: probing OpenGL crashes
    the process (a segmentation fault) on a machine without a display or GPU driver."""
    return [ti.cuda, ti.vulkan, ti.metal]


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
    _plain_source_positions()
    with contextlib.redirect_stdout(sys.stderr):
        ti.init(
            arch=_gpu_arches() if arch == "gpu" else getattr(ti, _ARCHES[arch]),
            default_fp=ti.f32,
            default_ip=ti.i32,
            offline_cache=True,
            offline_cache_file_path=str(cache_dir() / "ticache"),
            debug=debug,
            # Taichi's advanced IR passes made the surface-contact kernels take about 50 s to
            # compile on an empty cache (the demo's first run: 57 s against 4.5 s without them);
            # the unbreakable 13 rings' frames measured within 2 % either way.
            advanced_optimization=False,
            # (Taichi's "falling back to CPU" warning is replaced by the ArchError below;
            # a TI_LOG_LEVEL set in the environment is the user's, and Taichi warns when
            # ti.init overrides it)
            **({} if "TI_LOG_LEVEL" in os.environ else {"log_level": ti.WARN if arch == "cpu" else ti.ERROR}),
        )
    if "TI_LOG_LEVEL" not in os.environ:
        ti.set_logging_level(ti.WARN)
    got = ti.lang.impl.current_cfg().arch
    if got not in _arches_of(arch):
        # Taichi fell back to the CPU; an explicit arch that cannot be had is an error.
        _initialised_arch = "cpu"
        raise ArchError(f"arch {arch!r} is not available on this machine (Taichi found no usable "
                        f"{_DEVICE_NAMES.get(arch, arch)} device or driver): use --arch cpu, "
                        "or simulation.arch = \"cpu\" in the scene")
    _initialised_arch = arch
    global SERIAL_SMALL_LOOPS
    SERIAL_SMALL_LOOPS = arch == "cpu"
    return arch


# Loops over bodies, contacts and buckets run serially on the CPU backend: there a
# parallel-for task costs more to dispatch than a serial pass over a few thousand items. Read by kernels at compile time
# (``ti.loop_config(serialize=runtime.SERIAL_SMALL_LOOPS)``), set by init().
SERIAL_SMALL_LOOPS = True


def is_initialised() -> bool:
    return _initialised_arch is not None


def finish() -> bool:
    """End Taichi's runtime: Taichi writes its offline cache of compiled kernels only then
    (or at a normal interpreter exit, which a process leaving by ``os._exit`` or stopped by
    a nanny never reaches). Every field and kernel goes with it: a process's last use of
    Taichi. Returns whether a runtime was running."""
    global _initialised_arch
    if _initialised_arch is None:
        return False
    ti.reset()
    _initialised_arch = None
    return True
