"""``taichi-frac render --movie``: frames joined into a GIF (Pillow) or an MP4 (H.264 through
imageio-ffmpeg), read back and compared with the frames written (no Blender needed)."""

from __future__ import annotations

import sys

import numpy as np
import pytest
from PIL import Image

from taichi_frac.cli import main
from taichi_frac.commands.render import write_movie

COLORS = [(200, 30, 30), (30, 200, 30), (30, 30, 200), (220, 220, 40)]


@pytest.fixture
def frames(tmp_path):
    paths = []
    for i, color in enumerate(COLORS):
        image = np.zeros((48, 64, 3), np.uint8)
        image[:] = color
        image[:8, :8] = 255  # a corner marker, so no two frames are one flat colour
        path = tmp_path / f"frame_{i:04d}.png"
        Image.fromarray(image).save(path)
        paths.append(path)
    return paths


def test_gif_has_every_frame_at_the_frame_rate(frames, tmp_path):
    movie = tmp_path / "out.gif"
    write_movie(frames, movie, fps=12.5)
    gif = Image.open(movie)
    assert gif.n_frames == len(COLORS) and gif.size == (64, 48)
    for i, color in enumerate(COLORS):
        gif.seek(i)
        assert gif.info["duration"] == 80  # 1 / 12.5 s
        centre = np.asarray(gif.convert("RGB"))[24, 40]
        assert np.abs(centre.astype(int) - color).max() <= 8, (i, centre)


def test_mp4_has_every_frame_at_the_frame_rate(frames, tmp_path):
    import imageio_ffmpeg

    movie = tmp_path / "out.mp4"
    write_movie(frames, movie, fps=25)
    reader = imageio_ffmpeg.read_frames(str(movie))
    meta = reader.__next__()
    assert meta["size"] == (64, 48) and meta["fps"] == pytest.approx(25)
    decoded = [np.frombuffer(f, np.uint8).reshape(48, 64, 3) for f in reader]
    assert len(decoded) == len(COLORS)
    for image, color in zip(decoded, COLORS):
        # H.264 in yuv420p is lossy: the flat part of each frame within a few levels.
        assert np.abs(image[30:, 20:].reshape(-1, 3).mean(0) - color).max() < 12


def test_movie_frames_must_share_one_size(frames, tmp_path):
    Image.new("RGB", (32, 32)).save(frames[2])
    with pytest.raises(ValueError, match="32x32"):
        write_movie(frames, tmp_path / "out.mp4", fps=25)


def test_render_rejects_an_unknown_movie_format(tmp_path, capsys):
    cache = tmp_path / "c.usdc"
    cache.write_bytes(b"")
    code = main(["render", str(cache), "--movie", str(tmp_path / "out.avi"), "--blender-python", sys.executable])
    assert code == 2 and "must end in .mp4 or .gif" in capsys.readouterr().err
    code = main(["render", str(cache), "--resolution", "wide", "--blender-python", sys.executable])
    assert code == 2 and "bad --resolution" in capsys.readouterr().err
