"""Build the installable Blender extension zip: dist/taichi_frac_blender-<version>.zip.

    .venv/bin/python scripts/build_addon.py [--out-dir DIR]

Same layout as ``blender --command extension build``: blender_manifest.toml and the package's
__init__.py at the zip root (no enclosing folder), Python sources only (no __pycache__).
Install it in Blender from Edit > Preferences > Get Extensions > Install from Disk.
"""

from __future__ import annotations

import argparse
import sys
import tomllib
import zipfile
from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parents[1] / "blender_addon" / "taichi_frac_blender"
INCLUDE_SUFFIXES = {".py", ".toml"}


def build(out_dir: Path) -> Path:
    manifest = tomllib.loads((PACKAGE_DIR / "blender_manifest.toml").read_text())
    out_dir.mkdir(parents=True, exist_ok=True)
    target = out_dir / f"{manifest['id']}-{manifest['version']}.zip"
    files = sorted(
        p for p in PACKAGE_DIR.rglob("*")
        if p.is_file() and p.suffix in INCLUDE_SUFFIXES and "__pycache__" not in p.parts
    )
    tmp = target.with_suffix(".zip.tmp")
    with zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_DEFLATED) as archive:
        for path in files:
            # Fixed timestamp: the same sources give the same zip.
            info = zipfile.ZipInfo(path.relative_to(PACKAGE_DIR).as_posix(), date_time=(2020, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            archive.writestr(info, path.read_bytes())
    tmp.replace(target)
    return target


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out-dir", type=Path, default=Path(__file__).resolve().parents[1] / "dist")
    args = parser.parse_args(argv)
    print(build(args.out_dir))
    return 0


if __name__ == "__main__":
    sys.exit(main())
