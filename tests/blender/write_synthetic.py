"""Write the synthetic cache of synthetic.py with taichi_frac's CacheWriter (main env).

    python tests/blender/write_synthetic.py OUT.usdc [--up-axis Y] [--meters-per-unit 0.01]
        [--kill-after-frame N] [--checkpoint-every K]

--kill-after-frame sends SIGKILL to itself right after that frame (crash test).
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import synthetic  # noqa: E402

from taichi_frac.io import CacheWriter  # noqa: E402


def write(path, up_axis="Z", meters_per_unit=1.0, checkpoint_every=10, kill_after_frame=None):
    ids = {}
    with CacheWriter(path, fps=synthetic.FPS, start_frame=synthetic.START_FRAME, up_axis=up_axis,
                     meters_per_unit=meters_per_unit, checkpoint_every=checkpoint_every) as writer:
        def add(name):
            birth, _, parent, half = synthetic.FRAGMENTS[name]
            vertices, faces = synthetic.box_mesh(half)
            inner = [i in synthetic.INNER_FACES[name] for i in range(len(faces))]
            ids[name] = writer.add_fragment(
                name, vertices, faces, inner, birth,
                parent=None if parent is None else ids[parent],
                impact=None if parent is None else synthetic.IMPACT,
                peak_principal_stress=synthetic.peak_stress(name),
                face_peak_stress=synthetic.face_stress(name, len(faces)),
            )

        for frame in range(synthetic.START_FRAME, synthetic.END_FRAME + 1):
            for name, (birth, death, _, _) in synthetic.FRAGMENTS.items():
                if birth == frame:
                    add(name)
                if death == frame:
                    writer.end_fragment(ids[name], frame)
            live = [n for n in synthetic.FRAGMENTS if synthetic.alive(n, frame)]
            poses = [synthetic.pose(n, frame) for n in live]
            writer.write_frame(frame, [ids[n] for n in live], [p for p, _ in poses], [q for _, q in poses])
            if kill_after_frame is not None and frame == kill_after_frame:
                print(f"killing after frame {frame}", flush=True)
                os.kill(os.getpid(), signal.SIGKILL)
    return ids


if __name__ == "__main__":
    parser = argparse.ArgumentParser()
    parser.add_argument("out")
    parser.add_argument("--up-axis", default="Z")
    parser.add_argument("--meters-per-unit", type=float, default=1.0)
    parser.add_argument("--checkpoint-every", type=int, default=10)
    parser.add_argument("--kill-after-frame", type=int)
    args = parser.parse_args()
    write(args.out, args.up_axis, args.meters_per_unit, args.checkpoint_every, args.kill_after_frame)
