"""``taichi-frac run SCENE.toml``: simulate a scene end to end and write its USD cache."""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

HELP = "simulate a scene (TOML) with fracture and write a USD cache"
#: What --draft sets: every object's pieces cut without the volume fit.
DRAFT_OVERRIDE = "objects.*.fracture.crack_fit_rounds=0"


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "run", help=HELP, description=HELP + ". Ctrl-C stops cleanly and keeps a valid cache of the frames done.",
    )
    p.add_argument("scene", help="scene file (.toml), or a built-in scene: single_ring, thirteen_rings, glass_walls")
    p.add_argument("-o", "--output", help="cache file (.usdc/.usda); default: the scene's [output] path")
    p.add_argument("--arch", choices=["cpu", "cuda", "vulkan", "metal", "gpu"],
                   help="Taichi backend (default: the scene's simulation.arch, cpu)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scene value, e.g. --set ring.fracture.crack_count=3 "
                        "--set ring.material.tensile_strength=2e6 --set simulation.duration=1 (repeatable); "
                        "VALUE none restores the default, e.g. --set ring.fracture.crack_length=none")
    p.add_argument("--draft", action="store_true",
                   help="a quick look: cut the broken pieces on the cracks as the analysis placed them, without "
                        "the cuts that fit each piece's volume to its tets' (the same physics, done sooner; "
                        "large pieces a few per cent off their volume). Same as --set "
                        f"{DRAFT_OVERRIDE}")
    p.add_argument("--frames", type=int, help="simulate only this many frames (default: duration x fps)")
    p.add_argument("--no-fracture", action="store_true", help="treat every body as unbreakable")
    p.add_argument("--single-scale", action="store_true",
                   help="collide with every surface particle instead of the boundary layer (for comparison)")
    p.add_argument("--stats-json", metavar="FILE", help="also write the run summary as JSON")
    p.add_argument("--no-output", action="store_true", help="write no cache (benchmarking)")
    p.add_argument("--overwrite", action="store_true",
                   help="write the cache even while another run holds its lock (that run then stops)")
    p.add_argument("--surface-workers", type=int, default=None, metavar="N",
                   help="processes that cut the broken pieces' render surfaces while the frames go on (0: in "
                        "this process; default: four, or one per core on more, at most one per breakable "
                        "object); the cache is the same either way")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    p.add_argument("--progress-json", action="store_true",
                   help="report progress as one JSON object a frame on stderr, for programs that run this "
                        "command (the Blender add-on): {\"frame\", \"frames\", \"time\", \"fragments\", \"fps\"}; "
                        "stages besides the frames as {\"stage\": ...}: {\"stage\": \"prepare\", \"objects\"} "
                        "first, {\"stage\": \"surfaces\", \"left\", \"splits\"} while the last pieces' "
                        "surfaces are cut")
    p.set_defaults(func=main)


def _progress_printer(quiet: bool, as_json: bool = False):
    """A progress callback: a rich bar on a terminal, a line every 10 % otherwise, or with
    ``as_json`` one JSON line a frame (flushed, so a reading program sees each frame at once)."""
    if as_json:
        def cb(frame, total, t, frags, fps):
            print(json.dumps({"frame": frame, "frames": total, "time": round(t, 6), "fragments": frags,
                              "fps": round(fps, 3)}), file=sys.stderr, flush=True)

        return cb, None
    if quiet:
        return None, None
    if sys.stderr.isatty():
        from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

        bar = Progress(
            TextColumn("frame {task.completed:>4.0f}/{task.total:.0f}"), BarColumn(),
            TextColumn("t={task.fields[t]:.2f} s  fragments={task.fields[frags]}  {task.fields[fps]:.1f} fps"),
            TimeRemainingColumn(), transient=False,
        )
        task = None

        def cb(frame, total, t, frags, fps):
            nonlocal task
            if task is None:
                bar.start()
                task = bar.add_task("run", total=total, t=0.0, frags=0, fps=0.0)
            bar.update(task, completed=frame, t=t, frags=frags, fps=fps)

        return cb, bar

    last = [-1]

    def cb(frame, total, t, frags, fps):
        step = max(1, total // 10)
        if frame == total or frame // step != last[0]:
            last[0] = frame // step
            print(f"frame {frame}/{total}  t={t:.2f} s  fragments={frags}  {fps:.1f} fps", file=sys.stderr,
                  flush=True)

    return cb, None


def _surfaces_printer(args):
    """The run's ``surfaces_progress``: while the frames are done and the cache waits for
    the pieces' surfaces still being cut, how many splits are left (a stage line)."""
    last = [-1.0]

    def cb(left, splits):
        # (a line a second at most on a terminal, and the last; a program reading JSON gets each)
        now = time.monotonic()
        if args.progress_json or left == 0 or now - last[0] >= 1.0:
            last[0] = now
            _stage_line(args, "surfaces", f"frames done; cutting the pieces' surfaces: {left} of {splits} "
                                          "splits left", left=left, splits=splits)

    return cb


def _stage_line(args, stage: str, text: str, **fields) -> None:
    """A progress line outside the frames (a long set-up shows at once that the run has
    started; the wait for the last surfaces shows what is left): ``text`` on stderr, or a
    JSON object ``{"stage": stage, ...}`` with ``--progress-json`` (programs that read the
    frames' lines skip it); none with -q."""
    if args.progress_json:
        print(json.dumps({"stage": stage} | fields), file=sys.stderr, flush=True)
    elif not args.quiet:
        print(text, file=sys.stderr, flush=True)


def print_summary(summary, file=None) -> None:
    """The run's summary as a two-column table on ``file`` (default: sys.stdout at call
    time, so a redirected stdout receives it)."""
    file = sys.stdout if file is None else file
    s = summary
    rows = [
        ("scene", s.scene), ("frames", f"{s.frames} ({s.simulated_time:.2f} s simulated)"),
        ("physics particles", s.physics_particles), ("physics surface particles", s.surface_particles),
        ("boundary particles", s.boundary_particles), ("fragments", s.fragments), ("fracture events", s.fractures),
        ("substeps simulated again", f"{s.resimulated_substeps} (simulation.resimulate_fractures)"),
        ("ms per frame (mean / max)", f"{s.ms_per_frame['mean']:.2f} / {s.ms_per_frame['max']:.2f}"),
    ]
    if s.ms_per_frame.get("mean_after_first") is not None:
        rows += [
            ("  first frame", f"{s.ms_per_frame['first']:.2f} (in a new process, the dynamics kernels' first launch)"),
            ("  the later frames (mean / max)",
             f"{s.ms_per_frame['mean_after_first']:.2f} / {s.ms_per_frame['max_after_first']:.2f}"
             + (" (with the first impact's frame, which launches the fracture kernels)" if s.fractures else "")),
        ]
    rows += [
        ("wall time", f"{s.wall_time:.2f} s"),
        ("mass initial / final + dropped", f"{s.mass_initial:.6g} / {s.mass_final:.6g} + {s.mass_dropped:.3g} kg"),
    ]
    stage = s.stage_seconds
    dyn = s.dynamics_stage_seconds
    rows += [
        ("  prepare (mesh + model)", f"{stage.get('prepare', 0):.3f} s"),
        ("  set-up (World, surface workers)", f"{stage.get('setup', 0):.3f} s"),
        ("  collision (broad + narrow phase)", f"{dyn.get('collision', 0):.3f} s"),
        ("  contact response + integration", f"{dyn.get('response', 0):.3f} s"),
        ("  fracture analysis", f"{stage['fracture_analysis']:.3f} s"),
        ("  fragment split", f"{stage['fragment_split']:.3f} s"),
    ]
    if stage.get("render_surfaces", 0.0) > 0.0 and s.surface_workers == 0:  # (a cache was written, a body broke)
        rows.append(("    of which render surfaces", f"{stage['render_surfaces']:.3f} s (the pieces' surfaces cut "
                                                    "along the cracks)"))
    elif stage.get("render_surfaces", 0.0) > 0.0:
        rows.append(("  render surfaces", f"{stage['render_surfaces']:.3f} s in {s.surface_workers} worker "
                                          f"process(es) beside the frames; waited {stage['surfaces_wait']:.3f} s "
                                          "for them at the end"))
    rows += [
        ("  output", f"{stage['output']:.3f} s"),
    ]
    if s.output:
        rows.append(("cache", s.output + ("  (interrupted: frames done so far)" if s.interrupted else "")))
    width = max(len(k) for k, _ in rows)
    for k, v in rows:
        print(f"{k:<{width}}  {v}", file=file)


def unbroken_bodies(sim, frame_dt: float) -> list[dict]:
    """Why each breakable scene body that never broke did not (``fracture.peaks.diagnose``)."""
    from ..fracture.peaks import diagnose

    live = [sim.records[b] for b in sim.world.body_ids]
    names = [r.name for r in live if r.breakable and r.generation == 0]
    stage = sim.fracture_stage
    return diagnose(None if stage is None else stage.peaks, names, frame_dt) if stage is not None else []


def print_unbroken(unbroken: list[dict], file=None) -> None:
    """One line per breakable body that did not break: why, and what would break it."""
    file = sys.stdout if file is None else file
    for entry in unbroken:
        print(f"did not break: {entry['name']}: {entry['note']}", file=file)
        if "point_world" in entry:
            point = ", ".join(f"{v:.4g}" for v in entry["point_world"])
            print(f"  peak at t = {entry['time']:.4g} s, world ({point}) m", file=file)


def main(args) -> int:
    """Every check of the command line, the scene, the output paths and the meshes comes
    before the first frame; problems raise the package's errors (``cli`` prints them, and
    has taken Ctrl-C over: see ``interrupts``)."""
    from ..io.output import OutputError, check_output_path, check_stats_path
    from ..options import OptionError
    from ..scenes import load_scene
    from ..simulation import Simulation

    if args.frames is not None and args.frames < 1:
        raise OptionError(f"--frames {args.frames}: simulate at least 1 frame")
    if args.surface_workers is not None and not 0 <= args.surface_workers <= 256:
        raise OptionError(f"--surface-workers {args.surface_workers}: give 0 (cut in this process) to 256")
    if args.stats_json:
        check_stats_path(args.stats_json)
    if args.output and not args.no_output:
        check_output_path(args.output)
    try:
        # (the draft's first: a --set of the same key wins)
        scene = load_scene(args.scene, [DRAFT_OVERRIDE] * bool(args.draft) + list(args.overrides))
    except FileNotFoundError as exc:
        raise OptionError(str(exc)) from None
    output = False if args.no_output else (Path(args.output) if args.output else None)
    cb, bar = _progress_printer(args.quiet, args.progress_json)
    _stage_line(args, "prepare", f"{scene.name}: preparing {len(scene.objects)} object(s)",
                objects=len(scene.objects))
    try:
        sim = Simulation(scene, output=output, arch=args.arch, progress=cb, frames=args.frames,
                         single_scale=True if args.single_scale else None, fracture=not args.no_fracture,
                         overwrite=args.overwrite, surface_workers=args.surface_workers,
                         surfaces_progress=_surfaces_printer(args))
        summary = sim.run()
    finally:
        if bar is not None:
            bar.stop()
    unbroken = unbroken_bodies(sim, scene.simulation.frame_dt)
    print_summary(summary)
    print_unbroken(unbroken)
    if args.stats_json:
        try:
            Path(args.stats_json).write_text(json.dumps(json.loads(summary.to_json()) | {"unbroken": unbroken},
                                                        indent=2))
        except OSError as exc:
            raise OutputError(f"--stats-json {args.stats_json!r}: {exc.strerror or exc}") from None
    return 130 if summary.interrupted else 0
