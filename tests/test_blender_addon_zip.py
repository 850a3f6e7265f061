"""The add-on zip has the layout Blender's "Install from Disk" expects (what
``blender --command extension build`` makes): manifest and package __init__ at the zip root,
a valid manifest, pure Python that imports neither taichi nor compiled code. Installing it in a
real Blender is done in test_blender_import.py."""

from __future__ import annotations

import ast
import sys
import tomllib
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "scripts"))
import build_addon  # noqa: E402

REQUIRED = {"schema_version", "id", "version", "name", "tagline", "maintainer", "type",
            "blender_version_min", "license"}


def test_zip_layout_and_manifest(tmp_path):
    path = build_addon.build(tmp_path)
    with zipfile.ZipFile(path) as archive:
        names = archive.namelist()
        manifest = tomllib.loads(archive.read("blender_manifest.toml").decode())
        sources = {n: archive.read(n).decode() for n in names if n.endswith(".py")}
    assert set(names) >= {"blender_manifest.toml", "__init__.py", "reader.py", "retime.py", "build.py", "materials.py",
                          "properties.py", "ui.py", "schema.py", "sim_properties.py", "sim_ui.py", "export.py",
                          "scene_toml.py", "runner.py", "simulate.py"}
    assert all("/" not in n for n in names), names  # flat: no enclosing folder
    assert all(n.endswith((".py", ".toml")) for n in names), names  # no compiled code, no caches
    assert REQUIRED <= set(manifest)
    assert manifest["id"] == "taichi_frac_blender" and manifest["type"] == "add-on"
    assert path.name == f"taichi_frac_blender-{manifest['version']}.zip"
    # Slotted actions (Action.slots, ActionKeyframeStrip.channelbag) came in Blender 4.4; the
    # Blender tests run on 4.4.0 too (TAICHI_FRAC_BLENDER_PYTHON, see tests/support/blender.py).
    assert tuple(int(p) for p in manifest["blender_version_min"].split(".")) >= (4, 4, 0)
    assert len(manifest["tagline"]) <= 64 and not manifest["tagline"].endswith((".", "!", "?"))
    assert all(lic.startswith("SPDX:") for lic in manifest["license"])
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert manifest["version"] == pyproject["project"]["version"]

    init = ast.parse(sources["__init__.py"])
    functions = {n.name for n in init.body if isinstance(n, ast.FunctionDef)}
    assert {"register", "unregister"} <= functions
    for name, source in sources.items():
        for node in ast.walk(ast.parse(source)):
            modules = [a.name for a in node.names] if isinstance(node, ast.Import) else (
                [node.module or ""] if isinstance(node, ast.ImportFrom) and node.level == 0 else [])
            assert not any(m.split(".")[0] in ("taichi", "taichi_frac") for m in modules), (name, modules)


def test_zip_is_reproducible(tmp_path):
    first = build_addon.build(tmp_path / "a").read_bytes()
    second = build_addon.build(tmp_path / "b").read_bytes()
    assert first == second
