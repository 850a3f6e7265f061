"""The contact sheet: every done variant's last frame, small, labelled, on one PNG.

The frames are rendered by Blender (the add-on's importer and ``render_cache.py``'s camera
and lights, Cycles on the CPU) in one Blender process for the whole sweep
(``blender_addon/render_thumbnails.py``), each into its variant's folder as
``last_frame.png``; a variant that has one is not rendered again. Pillow lays them out
in sweep order, each under a label with its settings, fragment count and id.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import tempfile
from pathlib import Path

from . import results
from .variants import Variant

THUMBNAIL_SCRIPT = Path(__file__).resolve().parents[1] / "blender_addon" / "render_thumbnails.py"
SHEET_NAME = "sheet.png"


def render_thumbnails(jobs: list[tuple[Path, Path]], *, resolution: str, samples: int,
                      blender_python: Path | None = None) -> None:
    """Render the last frame of each cache to its PNG in one Blender process."""
    from ..commands.render import default_blender_python

    python = Path(blender_python or default_blender_python())
    if not python.exists():
        raise RuntimeError(f"no Blender Python at {python} (set TAICHI_FRAC_BLENDER_PYTHON, or run the sweep "
                           "with --no-sheet)")
    with tempfile.NamedTemporaryFile("w", suffix=".json", delete=False) as fh:
        json.dump([[str(c), str(p)] for c, p in jobs], fh)
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)  # the main environment's pxr must not reach Blender
    try:
        done = subprocess.run([str(python), str(THUMBNAIL_SCRIPT), fh.name, "--resolution", resolution,
                               "--samples", str(samples)], env=env, capture_output=True, text=True)
    finally:
        os.unlink(fh.name)
    if done.returncode != 0 and not any(p.exists() for _, p in jobs):
        raise RuntimeError(f"Blender rendered nothing (exit {done.returncode}): {done.stderr.strip()[-2000:]}")


def contact_sheet(result, *, resolution: str = "200x150", samples: int = 8, columns: int | None = None,
                  blender_python: Path | None = None, log=print) -> Path:
    """Render the missing thumbnails of ``result``'s done variants and write DIR/sheet.png."""
    from PIL import Image, ImageDraw

    directory = Path(result.directory)
    done = result.done
    jobs = [(directory / r["id"] / r["cache"], directory / r["id"] / results.THUMBNAIL_NAME) for r in done]
    missing = [(c, p) for c, p in jobs if not p.exists()]
    if missing:
        log(f"sweep: rendering {len(missing)} last frames with Blender for the contact sheet")
        render_thumbnails(missing, resolution=resolution, samples=samples, blender_python=blender_python)
    width, height = (int(v) for v in resolution.lower().split("x"))
    columns = columns or max(1, min(len(done), math.ceil(math.sqrt(len(done) * 1.5))))
    rows = math.ceil(len(done) / columns)
    font = _font(max(10, height // 12))
    line = font.size + 3 if hasattr(font, "size") else 14
    label_height = 2 * line + 6
    sheet = Image.new("RGB", (columns * width, rows * (height + label_height)), "white")
    draw = ImageDraw.Draw(sheet)
    for k, (record, (_, png)) in enumerate(zip(done, jobs)):
        x, y = (k % columns) * width, (k // columns) * (height + label_height)
        if png.exists():
            with Image.open(png) as tile:
                sheet.paste(tile.convert("RGB").resize((width, height)), (x, y))
        else:
            draw.rectangle([x, y, x + width - 1, y + height - 1], fill=(200, 200, 200))
            draw.text((x + 6, y + 6), "not rendered", fill="black", font=font)
        label = Variant(record["id"], record["index"], record["settings"]).label()
        draw.text((x + 4, y + height + 2), _fit(draw, label, font, width - 8), fill="black", font=font)
        draw.text((x + 4, y + height + 2 + line), f"{record['fragments']} fragments  {record['id']}",
                  fill=(60, 60, 60), font=font)
    path = directory / SHEET_NAME
    sheet.save(path)
    log(f"sweep: contact sheet {path} ({len(done)} variants)")
    return path


def _font(size: int):
    from PIL import ImageFont

    try:
        return ImageFont.load_default(size=size)
    except TypeError:  # Pillow without FreeType: the fixed bitmap font
        return ImageFont.load_default()


def _fit(draw, text: str, font, width: int) -> str:
    """``text`` cut with an ellipsis to fit ``width`` pixels."""
    if draw.textlength(text, font=font) <= width:
        return text
    while text and draw.textlength(text + "…", font=font) > width:
        text = text[:-1]
    return text + "…"
