"""The documentation site: its strict build (every warning an error: broken links, missing
pages, API docstrings that do not parse, scene-file keys without a docstring entry) and the
scene-file reference generated from the option dataclasses, checked against the classes."""

from __future__ import annotations

import dataclasses
import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import pytest

from taichi_frac.options import FractureOptions, Material, SimulationOptions, check_range
from taichi_frac.scenes import reference

ROOT = Path(__file__).resolve().parents[1]


def _needs_mkdocs():
    if importlib.util.find_spec("mkdocs") and importlib.util.find_spec("mkdocstrings_handlers"):
        return
    message = 'mkdocs missing: pip install -e ".[test]" (scripts/test.sh does)'
    if os.environ.get("CI", "").lower() == "true":
        pytest.fail(message)
    pytest.skip(message)


def test_site_builds_strict(tmp_path):
    _needs_mkdocs()
    env = dict(os.environ, PYTHONPATH=str(ROOT), NO_MKDOCS_2_WARNING="1")
    result = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
                            cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr[-4000:]
    page = (tmp_path / "site" / "reference" / "scene-file" / "index.html").read_text()
    # The generated tables are in the page: a key of each section and a range read from the code.
    for key in ("target_particles", "crack_count", "substep_motion_fraction", "half_extents", "checkpoint_seconds"):
        assert f"<code>{key}</code>" in page, key
    assert "[1, 64]" in page
    cli = (tmp_path / "site" / "reference" / "cli" / "index.html").read_text()
    assert "taichi-frac render" in cli and "--movie" in cli


def test_reference_has_every_key_with_its_default():
    text = reference.scene_file_reference()
    assert reference.undocumented_keys() == []
    for _, _, cls, skip in reference.SECTIONS:
        table = reference.section_table(cls, skip)
        rows = {line.split("|")[1].strip().strip("`"): line for line in table.splitlines()[2:]}
        names = [f.name for f in dataclasses.fields(cls) if f.init and f.name not in skip and f.name != "source_path"]
        assert list(rows) == names
        assert table in text
    fracture = reference.section_table(FractureOptions)
    row = next(line for line in fracture.splitlines() if line.startswith("| `crack_count`"))
    assert '| `"auto"` |' in row and "[1, 64]" in row
    row = next(line for line in fracture.splitlines() if line.startswith("| `crack_length`"))
    assert "(optional)" in row and "| m |" in row and "(0, inf)" in row


def test_allowed_values_read_from_the_validation():
    """The ranges come from __post_init__: open and closed ends, expressions, choices; each
    one checked against what the class really accepts."""
    ranges = reference.allowed_values(Material)
    assert ranges["poisson_ratio"] == "[0, 0.5)"
    assert ranges["density"] == "(0, inf)"
    assert ranges["look"].split(", ")[0] == "`glass`"
    for bad in (0.5, -0.01):
        with pytest.raises(ValueError):
            Material(poisson_ratio=bad)
    Material(poisson_ratio=0.0)
    simulation = reference.allowed_values(SimulationOptions)
    assert simulation["max_substeps"] == "[substeps, 100,000]"
    assert simulation["arch"] == "`cpu`, `cuda`, `vulkan`, `metal`, `gpu`"
    assert reference.allowed_values(FractureOptions)["small_fragment_policy"] == "`merge`, `debris`, `drop`"


def test_undocumented_and_unranged_fields_are_seen(monkeypatch):
    """A field without a docstring entry is reported; a docstring entry's unit is read."""

    @dataclasses.dataclass(frozen=True, kw_only=True)
    class Toy:
        """A toy.

        Attributes:
            width: how wide [m], in (0, 2].
        """

        width: float = 1.0
        height: float = 2.0

        def __post_init__(self):
            check_range("toy", "width", self.width, 0.0, 2.0, low_open=True)

    monkeypatch.setattr(reference, "SECTIONS", [("Toy", "[toy]", Toy, ())])
    assert reference.undocumented_keys() == ["[toy] height"]
    table = reference.section_table(Toy)
    assert "| `width` | number | `1` | m | (0, 2] | how wide [m], in (0, 2]. |" in table
