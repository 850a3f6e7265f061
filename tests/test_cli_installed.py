"""The package as installed, outside a checkout: what a wheel holds (the package's modules and
the package data pyproject.toml declares) copied into a folder of its own, imported by the
environment's ``taichi-frac`` entry point with the current folder a temporary one. There is
no tests/, scenes/ or pyproject.toml beside it, so a command that reaches for the checkout
fails here. Two processes: each pays Taichi's start-up."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
from pxr import Usd

from taichi_frac.io import schema
from taichi_frac.io.cache import check_cache

ROOT = Path(__file__).resolve().parents[1]
ENTRY = Path(sys.executable).parent / "taichi-frac"


def _install(site: Path) -> None:
    """Copy what ``pip install`` puts in site-packages: every module of ``taichi_frac`` and the
    files ``[tool.setuptools.package-data]`` declares, nothing else."""
    package_data = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"].get("package-data", {})
    files = [p for p in (ROOT / "taichi_frac").rglob("*.py") if "__pycache__" not in p.parts]
    for package, patterns in package_data.items():
        folder = ROOT.joinpath(*package.split("."))
        files += [p for pattern in patterns for p in folder.glob(pattern)]
    for source in files:
        target = site / source.relative_to(ROOT)
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(source, target)


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """(site folder, working folder, environment) of the installed copy."""
    if not ENTRY.exists():
        pytest.skip(f"no taichi-frac entry point beside {sys.executable} (pip install -e . makes it)")
    site, work = tmp_path_factory.mktemp("site"), tmp_path_factory.mktemp("work")
    _install(site)
    env = dict(os.environ, PYTHONPATH=str(site), PYTHONDONTWRITEBYTECODE="1")
    done = subprocess.run([sys.executable, "-c", "import taichi_frac; print(taichi_frac.__file__)"], cwd=work,
                          env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert Path(done.stdout.strip()) == site / "taichi_frac" / "__init__.py"  # the copy, not the checkout
    return site, work, env


def test_the_installed_package_holds_no_benchmarks(installed):
    """What the wheel installs (``[tool.setuptools.packages.find]``) is the simulator alone:
    the benchmark report stays in the checkout's benchmarks/ folder."""
    from setuptools import find_packages

    site, work, env = installed
    find = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"]["find"]
    packages = find_packages(str(ROOT), include=find["include"])
    assert "taichi_frac" in packages and not [p for p in packages if "bench" in p], packages
    assert not list(site.rglob("*bench*.py")) or all("commands" in p.parts for p in site.rglob("*bench*.py"))


def test_bench_outside_a_checkout_says_where_the_benchmarks_are(installed):
    site, work, env = installed
    done = subprocess.run([str(ENTRY), "bench", "dynamics", "--help"], cwd=work, env=env, capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 2
    assert "source checkout" in done.stderr and len(done.stderr.strip().splitlines()) == 1, done.stderr


def test_bench_in_the_checkout_finds_its_targets():
    if not ENTRY.exists():
        pytest.skip(f"no taichi-frac entry point beside {sys.executable} (pip install -e . makes it)")
    done = subprocess.run([str(ENTRY), "bench", "dynamics", "--help"], cwd=ROOT, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr
    assert "--scene" in done.stdout and "thirteen_rings" in done.stdout


@pytest.fixture(scope="module")
def ran(installed):
    """The installed copy's 3-frame ``run single_ring`` from its working folder: (process, cache)."""
    site, work, env = installed
    done = subprocess.run([str(ENTRY), "run", "single_ring", "--frames", "3", "-q"], cwd=work, env=env,
                          capture_output=True, text=True, timeout=600)
    return done, work / "single_ring.usdc"  # the scene's output.path, in the current folder


def test_a_built_in_scene_runs_from_any_folder_and_writes_its_cache_there(installed, ran):
    site, work, env = installed
    done, cache = ran
    assert done.returncode == 0, done.stderr
    assert cache.is_file(), (done.stdout, sorted(work.iterdir()))
    assert check_cache(cache) == []
    stage = Usd.Stage.Open(str(cache))
    data = stage.GetRootLayer().customLayerData[schema.LAYER_DATA_KEY]
    assert data[schema.KEY_COMPLETE] is True and data[schema.KEY_LAST_FRAME] == 3
    assert stage.GetEndTimeCode() == 3
    written = [p for p in site.rglob("*") if p.is_file() and p.suffix not in (".py", ".toml")]
    assert written == []  # nothing written into the installed package


BLENDER_PYTHON = ROOT / ".venv-blender" / "bin" / "python"


@pytest.mark.blender
def test_render_runs_outside_a_checkout(installed, ran):
    """The add-on and the script Blender runs ship in the package: ``taichi-frac render`` of the
    cache above, with only the Blender Python named, imports it through the add-on and writes
    the frame asked for, at the size asked for (the add-on's own tests check what it draws)."""
    if not BLENDER_PYTHON.exists():
        pytest.skip(f"no Blender environment at {BLENDER_PYTHON} (scripts/test.sh makes it)")
    site, work, env = installed
    done, cache = ran
    assert done.returncode == 0, done.stderr
    renders = work / "renders"
    shown = subprocess.run([str(ENTRY), "render", str(cache), "--frames", "3", "-o", str(renders),
                            "--resolution", "96x64", "--samples", "1"], cwd=work,
                           env=dict(env, TAICHI_FRAC_BLENDER_PYTHON=str(BLENDER_PYTHON)),
                           capture_output=True, text=True, timeout=600)
    assert shown.returncode == 0, shown.stdout[-2000:] + shown.stderr[-2000:]
    from PIL import Image
    import numpy as np

    image = np.asarray(Image.open(renders / "frame_0003.png").convert("RGB"), dtype=float)
    assert image.shape == (64, 96, 3)
    assert image.std() > 1.0  # a picture, not a blank
