"""`taichi-frac run`: the summary (Table 1's columns and the time per stage), --stats-json,
the cache, and Ctrl-C (a KeyboardInterrupt mid-run) leaving a valid cache of exactly the
frames done."""

from __future__ import annotations

import json

import pytest
from pxr import Usd

from taichi_frac.cli import main
from taichi_frac.io import schema
from taichi_frac.io.cache import check_cache
from taichi_frac.scenes import load_scene
from taichi_frac.scenes import BUILTIN_SCENE_DIR as SCENES
from taichi_frac.simulation import Simulation



@pytest.fixture
def shared_world(scene_world, monkeypatch):
    """The command builds its Simulation itself; here on the session's World (conftest.py),
    whose kernels are compiled already, instead of a new one."""
    import functools

    import taichi_frac.simulation as simulation

    monkeypatch.setattr(simulation, "Simulation", functools.partial(Simulation, world=scene_world))
    return scene_world


def test_run_prints_the_summary_and_writes_stats_json_and_a_cache(tmp_path, capsys, shared_world):
    out, stats = tmp_path / "ring.usdc", tmp_path / "stats.json"
    code = main(["run", str(SCENES / "single_ring.toml"), "--frames", "12", "-o", str(out),
                 "--stats-json", str(stats), "-q"])
    assert code == 0
    printed = capsys.readouterr().out
    for label in ("physics particles", "boundary particles", "fragments", "fracture events", "ms per frame",
                  "first frame", "the later frames", "collision", "contact response", "fracture analysis",
                  "fragment split", "output", "cache"):
        assert label in printed, label
    s = json.loads(stats.read_text())
    assert s["frames"] == 12 and s["interrupted"] is False and s["output"] == str(out)
    assert abs(s["mass_final"] + s["mass_dropped"] - s["mass_initial"]) <= 1e-9 * s["mass_initial"]
    ms = s["ms_per_frame"]  # the mean is the first frame and the later ones together
    assert abs(12 * ms["mean"] - (ms["first"] + 11 * ms["mean_after_first"])) <= 1e-9 * 12 * ms["mean"]
    assert ms["max"] == max(ms["first"], ms["max_after_first"])
    assert check_cache(out) == []
    stage = Usd.Stage.Open(str(out))
    data = stage.GetRootLayer().customLayerData[schema.LAYER_DATA_KEY]
    assert data[schema.KEY_COMPLETE] is True and data[schema.KEY_LAST_FRAME] == 12


def test_bad_override_exits_2_and_names_the_key(capsys):
    assert main(["run", str(SCENES / "single_ring.toml"), "--set", "ring.fracture.crack_count=0", "-q"]) == 2
    assert "crack_count" in capsys.readouterr().err


def test_draft_cuts_every_object_without_the_volume_fit(monkeypatch, capsys):
    """--draft is crack_fit_rounds = 0 on every object; a --set of one object still wins."""
    import taichi_frac.scenes as scenes
    from taichi_frac.options import OptionError

    loaded = []

    def load_and_stop(path, overrides=()):
        loaded.append(load_scene(path, overrides))
        raise OptionError("stopped after loading")

    monkeypatch.setattr(scenes, "load_scene", load_and_stop)
    assert main(["run", "thirteen_rings", "--draft", "--set", "ring03.fracture.crack_fit_rounds=1", "-q"]) == 2
    assert main(["run", "thirteen_rings", "-q"]) == 2
    draft, full = loaded
    assert [o.fracture.crack_fit_rounds for o in draft.objects] == [0, 0, 0, 1] + [0] * 9
    assert {o.fracture.crack_fit_rounds for o in full.objects} == {3}
    assert "stopped after loading" in capsys.readouterr().err


def test_ctrl_c_keeps_a_valid_cache_of_the_frames_done(tmp_path, scene_world):
    """Ctrl-C raises KeyboardInterrupt wherever the main thread is; here it comes from the
    progress callback, right after frame 5 was written."""
    out = tmp_path / "cut.usdc"
    sim = Simulation(load_scene(SCENES / "single_ring.toml"), output=out, frames=30, world=scene_world)

    def stop(frame, total, t, fragments, fps):
        if frame == 5:
            raise KeyboardInterrupt

    sim.progress = stop
    summary = sim.run()
    assert summary.interrupted and summary.frames == 5
    assert check_cache(out) == []
    stage = Usd.Stage.Open(str(out))
    data = stage.GetRootLayer().customLayerData[schema.LAYER_DATA_KEY]
    assert data[schema.KEY_COMPLETE] is False and data[schema.KEY_LAST_FRAME] == 5
    assert stage.GetEndTimeCode() == 5


def test_another_arch_than_the_running_one_is_refused(capsys):
    """Taichi runs on one arch per process. The scene's models used to be prepared (their
    SPH neighbour lists are a kernel) before the World chose the arch, so a run asked for
    cuda silently ran on the CPU; now the arch is chosen first, and asking for another
    than the one already running is an error naming both (exit 2 from the command)."""
    from taichi_frac import runtime

    assert runtime.init() == "cpu"  # the test session's
    assert main(["run", str(SCENES / "single_ring.toml"), "--arch", "cuda", "--frames", "1", "-q"]) == 2
    err = capsys.readouterr().err
    assert "'cpu'" in err and "'cuda'" in err
    with pytest.raises(runtime.ArchError, match="cuda"):
        Simulation(load_scene(SCENES / "single_ring.toml"), output=False, arch="cuda")
    assert runtime.init("cpu") == "cpu"


def test_a_ctrl_c_as_the_run_starts_gives_the_output_lock_back(tmp_path, monkeypatch, scene_world):
    """The first thing a run does (its garbage collection) interrupted: the run stops with
    nothing simulated and the lock file beside the cache is gone."""
    import taichi_frac.simulation as simulation

    class _InterruptedGc:
        @staticmethod
        def collect(generation=2):
            raise KeyboardInterrupt

        freeze = unfreeze = staticmethod(lambda: None)

    out = tmp_path / "ring.usdc"
    sim = Simulation(load_scene(SCENES / "single_ring.toml"), output=out, frames=2, world=scene_world,
                     surface_workers=0)
    assert (tmp_path / ".ring.usdc.lock").exists()
    monkeypatch.setattr(simulation, "gc", _InterruptedGc)
    try:
        summary = sim.run()
    except KeyboardInterrupt:
        pytest.fail("the Ctrl-C escaped the run")
    assert summary.interrupted and summary.frames == 0
    assert not (tmp_path / ".ring.usdc.lock").exists()


def test_a_ctrl_c_while_the_lock_is_taken_gives_it_back(tmp_path, monkeypatch):
    """SIGINT landing just after the lock file is written (the command's handler installed):
    the interrupt comes once the lock is the run's, and the run gives it back."""
    import signal

    from taichi_frac import interrupts
    from taichi_frac.io.output import OutputLock

    real = OutputLock.acquire

    def acquire_then_sigint(self, **kwargs):
        real(self, **kwargs)
        interrupts._handler(signal.SIGINT, None)  # (what the signal would run here)

    monkeypatch.setattr(OutputLock, "acquire", acquire_then_sigint)
    interrupts.install()
    try:
        with pytest.raises(KeyboardInterrupt):
            Simulation(load_scene(SCENES / "single_ring.toml"), output=tmp_path / "ring.usdc", frames=2)
    finally:
        interrupts.restore()
    assert not (tmp_path / ".ring.usdc.lock").exists()


@pytest.mark.parametrize("given, expected", [(None, ("1", "4")), (("3", "20"), ("3", "20"))])
def test_the_command_runs_one_openblas_thread_unless_told_otherwise(given, expected):
    """The command sets OPENBLAS_NUM_THREADS (one thread: the cores are the frames' and the
    surface workers') and OPENBLAS_THREAD_TIMEOUT (idle threads sleep instead of spinning)
    before numpy loads OpenBLAS, and keeps values the user set: in a new interpreter, the
    variables as OpenBLAS reads them when numpy is first imported."""
    import os
    import subprocess
    import sys

    names = ("OPENBLAS_NUM_THREADS", "OPENBLAS_THREAD_TIMEOUT")
    env = {k: v for k, v in os.environ.items() if k not in names}
    if given is not None:
        env.update(zip(names, given))
    # (the package itself loads no numpy: the command's module sets the variables first)
    code = ("import sys, taichi_frac; early = 'numpy' in sys.modules; import os, taichi_frac.cli; "
            "print(early, os.environ['OPENBLAS_NUM_THREADS'], os.environ['OPENBLAS_THREAD_TIMEOUT'])")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True).stdout
    assert out.split()[-3:] == ["False", *expected]
