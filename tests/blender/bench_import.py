"""Benchmark for the README (not a timed test): write a 200-fragment x 250-frame cache with
CacheWriter, then time its import in Blender through the add-on.

    .venv/bin/python tests/blender/bench_import.py [--fragments 200] [--frames 250]
"""

from __future__ import annotations

import argparse
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np
import trimesh

from taichi_frac.io import CacheWriter

ROOT = Path(__file__).resolve().parents[2]


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--fragments", type=int, default=200)
    parser.add_argument("--frames", type=int, default=250)
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    shard = trimesh.creation.icosphere(subdivisions=2, radius=0.05)  # 320 triangles
    vertices, faces = np.asarray(shard.vertices), np.asarray(shard.faces)
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "bench.usdc"
        start = time.perf_counter()
        with CacheWriter(path, fps=25, checkpoint_every=25) as writer:
            inner = rng.random((args.fragments, len(faces))) < 0.3
            ids = [writer.add_fragment(f"shard_{i:03d}", vertices, faces, inner[i], birth_frame=i % 50)
                   for i in range(args.fragments)]
            velocity = rng.normal(size=(args.fragments, 3))
            axis = rng.normal(size=(args.fragments, 3))
            axis /= np.linalg.norm(axis, axis=1, keepdims=True)
            for frame in range(args.frames):
                t = frame / 25.0
                angle = 3.0 * t
                q = np.c_[np.full(args.fragments, np.cos(angle / 2)), np.sin(angle / 2) * axis]
                writer.write_frame(frame, ids, velocity * t, q)
        print(f"write: {args.fragments} fragments x {args.frames} frames in {time.perf_counter() - start:.2f} s, "
              f"{path.stat().st_size / 1e6:.1f} MB")
        run = subprocess.run([str(ROOT / ".venv-blender" / "bin" / "python"), str(ROOT / "tests/blender/time_import.py"),
                              str(path)], capture_output=True, text=True)
        print(run.stdout.strip().splitlines()[-1] if run.returncode == 0 else run.stdout + run.stderr)


if __name__ == "__main__":
    main()
