"""Fingerprints of the paper's five runs: a hash of every frame's poses and of the written cache.

A change that only moves work (a refactor, work done in another process) must leave both
the same. Usage: ``.venv/bin/python scripts/pose_hashes.py [OUT_DIR] [--only NAME]``.
Prints one line per run: name, fragments, pose hash, cache hash.
"""

from __future__ import annotations

import argparse
import hashlib
import subprocess
import sys
import tempfile
from pathlib import Path

RUNS = {
    "ring_cc1": ("single_ring", ["ring.fracture.crack_count=1"]),
    "ring_cc3": ("single_ring", ["ring.fracture.crack_count=3"]),
    "ring_cc5": ("single_ring", ["ring.fracture.crack_count=5"]),
    "thirteen_rings": ("thirteen_rings", []),
    "glass_walls": ("glass_walls", []),
}


def run_one(key: str, out_dir: Path) -> str:
    import numpy as np

    from taichi_frac.io.cache import cache_digest
    from taichi_frac.scenes import load_scene
    from taichi_frac.simulation import Simulation

    scene_name, overrides = RUNS[key]
    out = out_dir / f"{key}.usdc"
    out.unlink(missing_ok=True)
    h = hashlib.sha256()
    sim = None

    def progress(frame, *_):
        ids = sim.world.body_ids
        state = sim.world.body_state(ids)
        h.update(np.asarray(ids, dtype=np.int64).tobytes())
        h.update(np.ascontiguousarray(state["position"]).tobytes())
        h.update(np.ascontiguousarray(state["orientation"]).tobytes())

    sim = Simulation(load_scene(scene_name, overrides), output=out, progress=progress, overwrite=True)
    summary = sim.run()
    return f"{key:16s} fragments {summary.fragments:3d} poses {h.hexdigest()[:12]} cache {cache_digest(out)[:12]}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out_dir", nargs="?", default=None)
    parser.add_argument("--only", choices=sorted(RUNS), default=None)
    parser.add_argument("--child", default=None, help=argparse.SUPPRESS)
    args = parser.parse_args()
    out_dir = Path(args.out_dir or tempfile.mkdtemp(prefix="pose_hashes_"))
    out_dir.mkdir(parents=True, exist_ok=True)
    if args.child:
        print(run_one(args.child, out_dir), flush=True)
        return
    for key in [args.only] if args.only else RUNS:
        # A fresh process per run: what a user's run meets.
        subprocess.run([sys.executable, __file__, str(out_dir), "--child", key], check=True)


if __name__ == "__main__":
    main()
