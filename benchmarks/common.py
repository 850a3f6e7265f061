"""What every part of the report shares: the context (one World, quick mode, where plots
go), progress lines, markdown tables, plots (matplotlib, Agg) and the machine description."""

from __future__ import annotations

import datetime
import functools
import os
import platform
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from taichi_frac.scenes import BUILTIN_SCENE_DIR as SCENES

#: The checkout the benchmarks run from: the report's files go to its docs/ and out/.
REPO = Path(__file__).resolve().parents[1]

#: Capacities of the report's one World: the largest scene of Tables 1-2 (13 breakable
#: rings: up to 13 + 256 x 13 bodies, ~50,000 collision particles with room for fragments)
#: and the 1,000-body pile fit; the same sizes as tests/test_scenes_end_to_end.py.
REPORT_WORLD = dict(max_bodies=4096, max_boundary_particles=200_000, max_contacts=400_000, max_static_boxes=8)


class Progress:
    """Progress lines on stderr: elapsed wall time and a message; ``frames(label)`` gives a
    Simulation progress callback that prints about every 25 % of a run."""

    def __init__(self, enabled: bool = True, stream=None):
        self.enabled = enabled
        self.stream = stream or sys.stderr
        self.start = time.perf_counter()

    def __call__(self, message: str) -> None:
        if self.enabled:
            print(f"[{time.perf_counter() - self.start:7.1f} s] {message}", file=self.stream, flush=True)

    def frames(self, label: str):
        last = [-1]

        def callback(frame, total, simulated, fragments, fps):
            quarter = 4 * frame // max(total, 1)
            if quarter != last[0] and (quarter > 0 or frame == 1):
                last[0] = quarter
                self(f"{label}: frame {frame}/{total}, t = {simulated:.2f} s, {fragments} fragments, "
                     f"{fps:.1f} frames/s")

        return callback


@dataclass
class Section:
    """One part of the report: its markdown body (numbers from the run), the plots it wrote
    and a few headline values for the summary."""

    key: str
    title: str
    markdown: str
    figures: list[Path] = field(default_factory=list)
    headline: dict = field(default_factory=dict)


@dataclass
class BenchContext:
    """Settings shared by the parts.

    Attributes:
        quick: a fast smoke version (fewer frames and sizes; numbers not meaningful).
        markdown_dir: folder of the markdown file; plot links are relative to it.
        figure_dir: where the PNG plots go.
        arch: Taichi backend.
        progress: the progress printer.
    """

    quick: bool = False
    markdown_dir: Path = REPO / "out" / "bench"
    figure_dir: Path = REPO / "out" / "bench" / "benchmarks"
    arch: str = "cpu"
    progress: Progress = field(default_factory=Progress)
    world_instance: object = None

    def world(self):
        """The report's one World (kernels compile once, ~8 s, then every run reuses them)."""
        if self.world_instance is None:
            from taichi_frac import runtime
            from taichi_frac.dynamics import World, WorldCapacity

            runtime.init(self.arch)
            self.world_instance = World(WorldCapacity(**REPORT_WORLD), arch=self.arch)
        return self.world_instance

    def save_figure(self, fig, name: str) -> tuple[Path, str]:
        """Write ``fig`` as ``figure_dir/name`` (PNG) and close it; returns the path and the
        link relative to the markdown file."""
        import matplotlib.pyplot as plt

        self.figure_dir.mkdir(parents=True, exist_ok=True)
        path = self.figure_dir / name
        fig.savefig(path, dpi=110, bbox_inches="tight")
        plt.close(fig)
        return path, os.path.relpath(path, self.markdown_dir)


def pyplot():
    """matplotlib.pyplot on the Agg backend (no display; plots are files)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def md_table(header: list[str], rows: list[list], align: str | None = None) -> str:
    """A markdown table; ``align`` is one character per column: l, r or c."""
    align = align or "l" + "r" * (len(header) - 1)
    marks = {"l": "---", "r": "---:", "c": ":---:"}
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join(marks[a] for a in align) + "|"]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def deepest_below_ground(world, bodies) -> float:
    """Deepest collision sphere below z = 0 over ``bodies`` of ``world`` [m] (0 when none
    is below)."""
    depth = 0.0
    for b in bodies:
        p = world.particle_state(b)
        depth = max(depth, float(np.max(p["radius"] - p["position"][:, 2])))
    return depth


def ms_pair(avg: float, peak: float) -> str:
    return f"{avg:.1f} / {peak:.1f}"


def warm_up(ctx: BenchContext) -> None:
    """Compile the dynamics kernels of the report's World and the fracture kernels (a short
    ring drop that breaks, run twice) so no timed run pays for compilation."""
    from taichi_frac.scenes import load_scene
    from taichi_frac.simulation import Simulation

    t0 = time.perf_counter()
    world = ctx.world()
    events = 0
    # Twice: fracture between frames, and inside the frame with the broken substep run
    # again (the glass walls), which use kernels of their own.
    for resimulate in ("false", "true"):
        scene = load_scene(SCENES / "single_ring.toml",
                           ["simulation.duration=0.8", f"simulation.resimulate_fractures={resimulate}"])
        events += Simulation(scene, output=False, world=world).run().fractures
    ctx.progress(f"warm-up (kernel compilation): {time.perf_counter() - t0:.1f} s, {events} fracture events")


def spread(values) -> str:
    """'median / 95th percentile / max' of ``values``, two decimals ('-' when empty)."""
    values = np.asarray(values, dtype=np.float64)
    if not len(values):
        return "-"
    return " / ".join(f"{v:.2f}" for v in (np.median(values), np.percentile(values, 95), values.max()))


def provenance() -> str:
    """'commit C, date, CPU with N cores': what a page written by its own command ran at."""
    info = machine_info()
    return f"commit {info['commit']}, {info['date']}, {info['cpu']} with {info['cores']} cores"


@functools.lru_cache(maxsize=1)
def machine_info() -> dict:
    """What the report ran on: CPU, cores, memory, versions, commit, date, load."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    memory_gb = None
    try:
        memory_gb = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30
    except (ValueError, OSError, AttributeError):
        pass
    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True,
                                text=True, timeout=10).stdout.strip()
        # Only what the measurements run (the report rewrites docs/ and README.md itself).
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no", "--",
                                "taichi_frac", "pyproject.toml"], cwd=REPO,
                               capture_output=True, text=True, timeout=10).stdout.strip()
        commit += " (with uncommitted changes)" if dirty else ""
    except (OSError, subprocess.SubprocessError):
        commit = "unknown"
    import taichi

    return dict(
        cpu=cpu, cores=os.cpu_count(), memory_gb=memory_gb, system=f"{platform.system()} {platform.release()}",
        python=platform.python_version(), taichi=".".join(map(str, taichi.__version__)),
        numpy=np.__version__, commit=commit or "unknown",
        date=datetime.datetime.now().astimezone().strftime("%Y-%m-%d %H:%M %Z"),
    )


def load_average() -> str:
    try:
        return " / ".join(f"{x:.2f}" for x in os.getloadavg())
    except OSError:
        return "n/a"
