"""``taichi-frac sweep SCENE --vary KEY=VALUES ... -o DIR``: many variants of a scene on Dask."""

from __future__ import annotations

import sys

HELP = "run many variants of a scene (seeds, crack counts, strengths) on Dask and collect them"


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "sweep", help=HELP,
        description=HELP + ". Each variant writes DIR/<variant id>/ (cache.usdc, stats.json, fragment_sizes.png); "
        "the sweep writes DIR/sweep.csv, DIR/sweep.json and the contact sheet DIR/sheet.png. Variants already "
        "done are skipped, so running the same command again after Ctrl-C does the rest.",
    )
    p.add_argument("scene", help="scene file (.toml), or a built-in scene: single_ring, thirteen_rings, glass_walls")
    p.add_argument("--vary", action="append", default=[], metavar="KEY=VALUES", required=True,
                   help="a scene key (as --set's) and its values: START:STOP integers (0:32 is 0..31), "
                        "V1,V2,... a list, LOW..HIGH a range (with --samples); repeatable: the sweep runs "
                        "the product, e.g. --vary ring.fracture.seed=0:32 --vary ring.fracture.crack_count=1,3,5")
    p.add_argument("-o", "--output", required=True, metavar="DIR", help="the sweep's folder")
    p.add_argument("--samples", type=int, metavar="N",
                   help="N random draws from the --vary values and ranges instead of their product")
    p.add_argument("--sweep-seed", type=int, default=0, metavar="S", help="seed of the --samples draws (default 0)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scene value in every variant (as taichi-frac run --set; repeatable)")
    p.add_argument("--frames", type=int, help="simulate only this many frames per variant (default: duration x fps)")
    p.add_argument("--workers", type=int, metavar="N",
                   help="local worker processes (default: one per core); each keeps its kernels between variants")
    p.add_argument("--scheduler", metavar="tcp://HOST:PORT",
                   help="run on an existing Dask cluster (its workers need taichi-frac and the same paths)")
    p.add_argument("--arch", default="cpu", choices=["cpu", "cuda", "vulkan", "metal", "gpu"],
                   help="Taichi backend of the workers (default cpu)")
    p.add_argument("--no-sheet", action="store_true", help="do not render the contact sheet")
    p.add_argument("--sheet-resolution", default="200x150", metavar="WxH",
                   help="size of each variant's picture on the sheet (default 200x150)")
    p.add_argument("--sheet-samples", type=int, default=8, help="Cycles samples of those pictures (default 8)")
    p.add_argument("--list", action="store_true", help="print the variants and their ids, run nothing")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=main)


def main(args) -> int:
    from pathlib import Path

    from ..options import OptionError
    from ..sweep.runner import sweep
    from ..sweep.variants import make_variants

    if args.list:
        try:
            variants = make_variants(args.vary, scene_name=Path(args.scene).name, fixed=tuple(args.overrides),
                                     frames=args.frames, samples=args.samples, seed=args.sweep_seed)
        except OptionError as exc:
            print(f"taichi-frac sweep: {exc}", file=sys.stderr)
            return 2
        for v in variants:
            print(f"{v.id}  {v.label()}")
        return 0
    try:
        result = sweep(args.scene, args.vary, args.output, samples=args.samples, seed=args.sweep_seed,
                       overrides=args.overrides, frames=args.frames, workers=args.workers, scheduler=args.scheduler,
                       arch=args.arch, sheet=not args.no_sheet, progress=not args.quiet,
                       sheet_options=dict(resolution=args.sheet_resolution, samples=args.sheet_samples))
    except (OptionError, FileNotFoundError) as exc:
        print(f"taichi-frac sweep: {exc}", file=sys.stderr)
        return 2
    counts = {s: sum(r["status"] == s for r in result.records) for s in ("done", "failed", "pending")}
    print(f"{counts['done']} done ({result.ran - result.failed} run now, {result.skipped} found done), "
          f"{counts['failed']} failed, {counts['pending']} not run; {result.seconds:.1f} s")
    print(f"results: {result.csv_path}  {result.json_path}" + (f"  {result.sheet}" if result.sheet else ""))
    for r in result.records:
        if r["status"] == "failed":
            print(f"  failed {r['id']} ({', '.join(f'{k}={v}' for k, v in r['settings'].items())}): {r['error']}")
    if result.interrupted:
        return 130
    return 1 if counts["failed"] else 0
