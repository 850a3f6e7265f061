"""The command line in a process of its own, where the exit status, stdout and signals are
the point: an arch that cannot be had (exit 2), ``--json`` alone on stdout, and Ctrl-C
during start-up (exit 130, never a finished run). A handful of processes: each pays
Taichi's start-up."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from taichi_frac.scenes import BUILTIN_SCENE_DIR as SCENES

ROOT = Path(__file__).resolve().parents[1]
RING = str(SCENES / "single_ring.toml")


def _command(*args: str) -> list[str]:
    return [sys.executable, "-m", "taichi_frac", *args]


def _env() -> dict:
    env = dict(os.environ)
    env.pop("TI_LOG_LEVEL", None)  # (the one conftest.py sets; a user's would be reported by Taichi)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    return env


@pytest.mark.skipif(shutil.which("nvidia-smi") is not None, reason="this machine may have a CUDA device")
def test_an_arch_that_cannot_be_had_is_an_error_not_a_fallback(tmp_path):
    done = subprocess.run(_command("run", RING, "--arch", "cuda", "--frames", "1", "-o", str(tmp_path / "x.usdc")),
                          capture_output=True, text=True, env=_env(), timeout=300)
    assert done.returncode == 2, done.stderr
    assert "arch 'cuda' is not available" in done.stderr and "Traceback" not in done.stderr
    assert not list(tmp_path.iterdir())  # nothing written, the lock given back


def test_info_json_is_alone_on_stdout():
    done = subprocess.run(_command("info", "torus", "--particles", "300", "--json"), capture_output=True, text=True,
                          env=_env(), timeout=300)
    assert done.returncode == 0, done.stderr
    report = json.loads(done.stdout)  # the whole of stdout is the one object
    assert report["physics_particles"] > 0
    assert "Warning" not in done.stderr and "[W " not in done.stderr, done.stderr


def test_ctrl_c_during_start_up_stops_the_run(tmp_path):
    """SIGINT while the command is still importing and preparing: exit 130, never a run
    that goes on to finish; a second SIGINT exits at once."""
    once = subprocess.Popen(_command("run", RING, "-o", str(tmp_path / "a.usdc"), "-q"), env=_env(),
                            stderr=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    twice = subprocess.Popen(_command("run", RING, "-o", str(tmp_path / "b.usdc"), "-q"), env=_env(),
                             stderr=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    time.sleep(1.5)
    once.send_signal(signal.SIGINT)
    twice.send_signal(signal.SIGINT)
    time.sleep(0.05)
    twice.send_signal(signal.SIGINT)
    _, err_twice = twice.communicate(timeout=60)
    _, err_once = once.communicate(timeout=300)
    # 130, or killed by the signal itself when it came as the interpreter exited (what a
    # shell also reports as 130)
    assert twice.returncode in (130, -signal.SIGINT), err_twice
    assert once.returncode == 130, err_once
    assert "interrupted" in err_once and "Traceback" not in err_once, err_once
    assert not (tmp_path / ".a.usdc.lock").exists()
