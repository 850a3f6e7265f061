"""Bad input is one line on stderr and exit status 2 before any work; no NaN or inf reaches
a cache; a cache says ``complete`` only when every frame was written; a run is
checkpointed right after its first frame; one run at a time writes an output.

One test (or a few) per problem a hostile user found, in the order they were reported:
preparation errors as tracebacks (1), loader crashes (2), extreme values reaching the
internals (3), NaN/inf in caches (4), crashed or empty runs marked complete (5), output
problems found after the simulation (6), Ctrl-C swallowed during start-up (7), the first
checkpoint too late (8). The arch (9) and the real Ctrl-C need a process of their own:
tests/test_bad_input_cli.py."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from pxr import Usd

from taichi_frac import interrupts
from taichi_frac.cli import main
from taichi_frac.geometry.meshio_in import load_surface
from taichi_frac.geometry.validate import MeshError
from taichi_frac.io import schema
from taichi_frac.io.cache import CacheWriter, NonFiniteError, check_cache
from taichi_frac.io.output import OutputError, OutputLock
from taichi_frac.options import OptionError, SimulationOptions
from taichi_frac.scenes import load_scene
from taichi_frac.scenes import BUILTIN_SCENE_DIR as SCENES
from taichi_frac.simulation import NonFinitePoseError, Simulation

RING = str(SCENES / "single_ring.toml")

SMALL_SCENE = """
name = "small"
[simulation]
fps = 50
duration = 0.2
[output]
path = "small.usdc"
checkpoint_every = 25
checkpoint_seconds = 1000.0
[[colliders]]
type = "ground"
[[objects]]
name = "puck"
primitive = "cylinder:radius=0.05,height=0.03"
breakable = false
position = [0.0, 0.0, 0.2]
[objects.particles]
target_particles = 200
"""


def _small_scene(tmp_path, text: str = SMALL_SCENE):
    path = tmp_path / "small.toml"
    path.write_text(text)
    return load_scene(path)


def _layer_data(path):
    stage = Usd.Stage.Open(str(path))
    return stage.GetRootLayer().customLayerData[schema.LAYER_DATA_KEY], stage


def _one_error_line(capsys, *needles):
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    lines = [line for line in err.splitlines() if "error" in line]
    assert len(lines) == 1, err
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])
    return lines[0]


# 1. run: problems found while preparing objects --------------------------------------------

def test_run_reports_a_bad_primitive_and_an_empty_mesh_in_one_line(tmp_path, capsys):
    assert main(["run", RING, "--set", "ring.primitive=torus:major=-1", "-o", str(tmp_path / "a.usdc"), "-q"]) == 2
    _one_error_line(capsys, "ring", "major", "-1")
    (tmp_path / "empty.obj").write_text("")
    scene = tmp_path / "mesh.toml"
    scene.write_text('[[objects]]\nname = "cup"\nmesh = "empty.obj"\nposition = [0, 0, 1]\n')
    assert main(["run", str(scene), "-o", str(tmp_path / "b.usdc"), "-q"]) == 2
    _one_error_line(capsys, "empty.obj", "empty")
    # Nothing written, and the output's lock given back.
    assert sorted(p.name for p in tmp_path.iterdir()) == ["empty.obj", "mesh.toml"]


def test_an_open_mesh_in_a_scene_is_told_the_scene_s_way_to_repair_it(tmp_path, capsys):
    # (a tetrahedron without its last face: one boundary loop of 3 edges)
    (tmp_path / "open.obj").write_text(_tetra_obj(0.1).rsplit("f ", 1)[0])
    scene = tmp_path / "open.toml"
    scene.write_text('[[objects]]\nname = "cup"\nmesh = "open.obj"\nposition = [0, 0, 1]\n')
    assert main(["run", str(scene), "-o", str(tmp_path / "c.usdc"), "-q"]) == 2
    line = _one_error_line(capsys, "object 'cup'", "not closed", "repair = true on object 'cup'",
                           "--set cup.repair=true")
    assert "--repair" not in line  # (taichi-frac run has no such flag)
    # The fix it names works.
    repaired = load_scene(scene, ["cup.repair=true"]).objects[0]
    assert repaired.prepare(use_cache=False)[0].volume == pytest.approx(0.1**3 / 6, rel=1e-6)


def test_debug_shows_the_traceback(tmp_path, capsys):
    assert main(["run", RING, "--set", "ring.primitive=torus:major=-1", "--debug", "-q",
                 "-o", str(tmp_path / "a.usdc")]) == 2
    assert "Traceback" in capsys.readouterr().err


# 2. loader crashes ----------------------------------------------------------------------------

@pytest.mark.parametrize("override, needle", [
    (f"ring.fracture.seed={10**400}", "beyond the largest 32-bit float"),
    ("objects.².friction=1", "no entry named '²'"),
    ("ring.material.density=1e39", "beyond the largest 32-bit float"),
])
def test_overrides_that_crashed_the_loader(override, needle):
    with pytest.raises(OptionError, match=needle):
        load_scene(RING, [override])


def test_scene_files_that_crashed_the_loader(tmp_path):
    latin = tmp_path / "latin.toml"
    latin.write_bytes(b'name = "caf\xe9"\n')
    with pytest.raises(OptionError, match=r"latin.toml: line 1: byte 0xe9 is not UTF-8"):
        load_scene(latin)
    with pytest.raises(OptionError, match="is a folder"):
        load_scene(tmp_path)
    bare = tmp_path / "bare.toml"
    bare.write_text('[[objects]]\nname = "ring"\nprimitive = "torus"\nposition = [0, 0, 1]\n')
    assert load_scene(bare, ["simulation.duration=0.5"]).simulation.duration == 0.5
    five = tmp_path / "five.toml"
    five.write_text("objects = 5\n")
    with pytest.raises(OptionError, match="objects must be an array"):
        load_scene(five, ["simulation.fps=3"])


# 3. extreme values ----------------------------------------------------------------------------

@pytest.mark.parametrize("spec, needle", [
    ("torus:major=1e308", "major = 1e\\+308 m"),
    ("sphere:radius=1e-300", "radius = 1e-300 m"),
    ("box:x=1e-12,y=1,z=1", "x = 1e-12 m"),
])
def test_primitive_sizes_the_mesher_cannot_take_are_refused(spec, needle):
    with pytest.raises(OptionError, match=needle):
        load_scene(RING, [f"ring.primitive={spec}"])


@pytest.mark.parametrize("value", ["nan", "0", "-1", "inf"])
def test_info_max_volume_must_be_positive_and_finite(value, capsys):
    assert main(["info", "torus", "--max-volume", value]) == 2
    _one_error_line(capsys, "--max-volume")


def _tetra_obj(size: float) -> str:
    return (f"v 0 0 0\nv {size} 0 0\nv 0 {size} 0\nv 0 0 {size}\n"
            "f 1 3 2\nf 1 2 4\nf 2 3 4\nf 1 4 3\n")


def test_mesh_read_errors_name_the_real_problem(tmp_path):
    tiny = tmp_path / "tiny.obj"
    tiny.write_text(_tetra_obj(1e-9))
    with pytest.raises(MeshError, match=r"'tiny.obj' is 1e-09 m across .*units"):
        load_surface(tiny)
    assert load_surface(tiny, scale=1e8).volume == pytest.approx(0.1**3 / 6, rel=1e-9)  # the hint works
    nan = tmp_path / "nan.obj"
    nan.write_text(_tetra_obj(1.0).replace("v 0 0 1", "v 0 0 nan"))
    with pytest.raises(MeshError, match=r"'nan.obj': 1 vertices with a NaN .* vertex 3"):
        load_surface(nan)
    noise = tmp_path / "noise.obj"
    noise.write_bytes(np.random.default_rng(0).integers(0, 256, 3000, dtype=np.uint8).tobytes())
    with pytest.raises(MeshError, match=r"'noise.obj' is not a text OBJ file"):
        load_surface(noise)
    latin = tmp_path / "latin.obj"  # an old exporter's Latin-1 comment is still a mesh
    latin.write_bytes(b"# caf\xe9\n" + _tetra_obj(0.1).encode())
    assert load_surface(latin).volume == pytest.approx(0.1**3 / 6, rel=1e-9)


# 4. NaN and inf in caches ---------------------------------------------------------------------

@pytest.mark.parametrize("override, needle", [
    ("ring.orientation=[1e200,1e200,0,0]", "beyond the largest 32-bit float"),
    ("ring.linear_velocity=[0,1e39,0]", "beyond the largest 32-bit float"),
    ("ring.angular_velocity=[0,-9.2e18,0]", "rad/s"),
    ("colliders.0.height=1e19", "out of range"),
    ("colliders.0.height=2", "below the ground"),
])
def test_values_the_simulation_cannot_represent_are_refused(override, needle):
    overrides = [override] + (["ring.euler_deg=none"] if "orientation" in override else [])
    with pytest.raises(OptionError, match=needle):
        load_scene(RING, overrides)


def test_a_huge_but_representable_quaternion_is_normalised():
    q = load_scene(RING, ["ring.euler_deg=none", "ring.orientation=[1e30,1e30,0,0]"]).objects[0].orientation
    np.testing.assert_allclose(q, [2**-0.5, 2**-0.5, 0, 0], rtol=1e-15)


def test_the_writer_never_writes_nan(tmp_path):
    path = tmp_path / "w.usda"
    vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float) * 0.1
    faces = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])
    writer = CacheWriter(path, fps=24)
    fid = writer.add_fragment("t", vertices, faces, np.zeros(4, bool), 0)
    writer.write_frame(0, [fid], [[0, 0, 1]], [[1, 0, 0, 0]])
    for position, quat in (([0, 0, np.nan], [1, 0, 0, 0]), ([0, 0, 1], [np.nan] * 4), ([np.inf, 0, 0], [1, 0, 0, 0])):
        with pytest.raises(NonFiniteError, match="frame 1"):
            writer.write_frame(1, [fid], [position], [quat])
    with pytest.raises(NonFiniteError):
        writer.add_fragment("bad", np.where(vertices == 0.1, np.nan, vertices), faces, np.zeros(4, bool), 1)
    with pytest.raises(NonFiniteError, match="32-bit"):  # (points are float32: 1e39 would be inf)
        writer.add_fragment("huge", vertices * 1e40, faces, np.zeros(4, bool), 1)
    writer.close(complete=False)
    text = path.read_text().lower()
    assert not re.search(r"\b-?(nan|inf)\b", text)
    data, stage = _layer_data(path)
    assert data[schema.KEY_LAST_FRAME] == 0 and data[schema.KEY_COMPLETE] is False


def test_a_non_finite_pose_stops_the_run_naming_body_and_frame(tmp_path, scene_world, monkeypatch):
    out = tmp_path / "nan.usdc"
    sim = Simulation(_small_scene(tmp_path), output=out, frames=6, world=scene_world)
    real = sim.world.body_state

    calls = []

    def poisoned(ids):  # (read once a frame, from frame 0 on, to write the poses)
        state = real(ids)
        if len(calls) >= 3:
            state["position"][0, 2] = np.nan
        calls.append(1)
        return state

    monkeypatch.setattr(sim.world, "body_state", poisoned)
    with pytest.raises(NonFinitePoseError, match=r"frame 3: body 'puck' has a non-finite pose"):
        sim.run()
    data, stage = _layer_data(out)
    assert data[schema.KEY_COMPLETE] is False and data[schema.KEY_LAST_FRAME] == 2
    assert check_cache(out) == []
    assert not (tmp_path / ".nan.usdc.lock").exists()


# 5. complete only when every frame was written ------------------------------------------------

def test_a_crashed_run_is_marked_incomplete(tmp_path, scene_world):
    out = tmp_path / "crash.usdc"
    sim = Simulation(_small_scene(tmp_path), output=out, frames=6, world=scene_world)

    def crash(frame, *_):
        if frame == 3:
            raise RuntimeError("contact normal must be a finite non-zero vector")

    sim.progress = crash
    with pytest.raises(RuntimeError, match="contact normal"):
        sim.run()
    data, _ = _layer_data(out)
    assert data[schema.KEY_COMPLETE] is False and data[schema.KEY_LAST_FRAME] == 3


def test_zero_and_negative_frame_counts_are_refused(tmp_path, capsys):
    with pytest.raises(OptionError, match="rounds to none"):
        SimulationOptions(fps=1, duration=0.4)
    for frames in ("0", "-1"):
        assert main(["run", RING, "--frames", frames, "-o", str(tmp_path / "z.usdc")]) == 2
        _one_error_line(capsys, f"--frames {frames}")
    with pytest.raises(OptionError, match="at least 1 frame"):
        Simulation(_small_scene(tmp_path), output=False, frames=0)
    assert not list(tmp_path.glob("*.usdc"))


# 6. output problems: found before any work ----------------------------------------------------

def test_output_paths_are_checked_before_anything_runs(tmp_path, capsys):
    (tmp_path / "folder").mkdir()
    (tmp_path / "file").write_text("")
    cases = [
        (["-o", str(tmp_path / "folder")], "is a folder"),
        (["-o", str(tmp_path / "shot.txt")], "must end in .usdc"),
        (["-o", str(tmp_path / "file" / "shot.usdc")], "is a file, not a folder"),
        (["--stats-json", str(tmp_path / "missing" / "s.json")], "does not exist"),
        (["--stats-json", str(tmp_path / "folder")], "is a folder"),
    ]
    for extra, needle in cases:
        # (a scene that would fail later, at meshing: the output is refused first)
        assert main(["run", RING, "--set", "ring.primitive=torus:major=-1", "-q"] + extra) == 2
        _one_error_line(capsys, needle)


@pytest.mark.skipif(os.name != "posix" or os.geteuid() == 0, reason="root writes into any folder")
def test_an_unwritable_folder_is_refused(tmp_path, capsys):
    locked = tmp_path / "ro"
    locked.mkdir(mode=0o500)
    assert main(["run", RING, "-o", str(locked / "x.usdc"), "-q"]) == 2
    _one_error_line(capsys, "not writable")


def test_a_second_run_on_one_output_refuses_unless_overwrite(tmp_path, capsys):
    out = tmp_path / "shot.usdc"
    other = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        lock = OutputLock(out)
        lock.lock_path.write_text(f"{other.pid} {lock.owner.split(' ', 1)[1]}\n")  # a live run holds it
        with pytest.raises(OutputError, match=f"being written by another run \\(process {other.pid}"):
            OutputLock(out).acquire()
        assert main(["run", RING, "-o", str(out), "--frames", "1", "-q"]) == 2
        _one_error_line(capsys, "--overwrite")
        taker = OutputLock(out)
        taker.acquire(overwrite=True)  # what --overwrite does
        assert taker.holder() == taker.owner
    finally:
        other.kill()
        other.wait()
    # The run it took over from stops at its next write instead of overwriting.
    first = OutputLock(tmp_path / "b.usdc")
    first.acquire()
    writer = CacheWriter(tmp_path / "b.usdc", fps=24, lock=first)
    OutputLock(tmp_path / "b.usdc").lock_path.write_text("1 elsewhere\n")
    with pytest.raises(OutputError, match="taken over"):
        writer.checkpoint()
    assert not (tmp_path / "b.usdc").exists()
    # A lock left by a killed run (its process gone) is taken over.
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    stale = OutputLock(tmp_path / "c.usdc")
    stale.lock_path.write_text(f"{dead.pid} {stale.owner.split(' ', 1)[1]}\n")
    stale.acquire()
    assert stale.holder() == stale.owner
    stale.release()
    assert not stale.lock_path.exists()
    # So is one whose killed process is a zombie nobody reaped (as in containers whose init
    # never reaps): it answers signal 0 but will never write again.
    zombie = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        zombie.kill()
        stat = Path(f"/proc/{zombie.pid}/stat")
        deadline = time.monotonic() + 10
        while stat.exists() and stat.read_text().rpartition(")")[2].split()[0] != "Z":
            assert time.monotonic() < deadline
            time.sleep(0.01)
        held = OutputLock(tmp_path / "d.usdc")
        held.lock_path.write_text(f"{zombie.pid} {held.owner.split(' ', 1)[1]}\n")
        held.acquire()
        assert held.holder() == held.owner
    finally:
        zombie.wait()


# 7. Ctrl-C during start-up --------------------------------------------------------------------

def test_a_swallowed_ctrl_c_still_stops_the_start_up(tmp_path, monkeypatch):
    before = signal.getsignal(signal.SIGINT)  # (SIG_IGN where the suite runs as a background job)
    interrupts.install()
    try:
        try:  # a dependency's ``except BaseException`` around the moment Ctrl-C comes
            os.kill(os.getpid(), signal.SIGINT)
            for _ in range(1000):
                pass
        except BaseException:
            pass
        assert interrupts.requested()
        with pytest.raises(KeyboardInterrupt):
            Simulation(_small_scene(tmp_path), output=tmp_path / "never.usdc", frames=2)
        assert not (tmp_path / ".never.usdc.lock").exists()
        def _exit(code):
            raise SystemExit(code)

        monkeypatch.setattr(os, "_exit", _exit)  # (what os._exit would do, without ending the tests)
        with pytest.raises(SystemExit) as exited:
            interrupts._handler(signal.SIGINT, None)  # a second Ctrl-C exits at once
        assert exited.value.code == 130
    finally:
        interrupts.restore()
    assert signal.getsignal(signal.SIGINT) is before


# 8. the first checkpoint ----------------------------------------------------------------------

def test_the_first_checkpoint_comes_right_after_the_first_frame(tmp_path, scene_world):
    """checkpoint_seconds is 1000 s: a kill after frame 1 still finds frames 0-1 on disk."""
    out = tmp_path / "early.usdc"
    sim = Simulation(_small_scene(tmp_path), output=out, frames=3, world=scene_world)
    seen = {}

    def look(frame, *_):
        if out.exists():
            copy = tmp_path / f"copy{frame}.usdc"  # (USD caches an opened layer by its path)
            copy.write_bytes(out.read_bytes())
            seen[frame] = _layer_data(copy)[0][schema.KEY_LAST_FRAME]

    sim.progress = look
    sim.run()
    assert seen == {1: 1, 2: 1, 3: 1}
    data, _ = _layer_data(out)
    assert data[schema.KEY_COMPLETE] is True and data[schema.KEY_LAST_FRAME] == 3


def test_ctrl_c_in_a_deferred_block_comes_when_the_block_ends():
    """A first Ctrl-C inside ``interrupts.deferred`` (an import whose library would print it
    as a traceback) only sets the flag; the KeyboardInterrupt comes at the block's end."""
    interrupts.install()
    try:
        reached_end = False
        with pytest.raises(KeyboardInterrupt):
            with interrupts.deferred():
                os.kill(os.getpid(), signal.SIGINT)
                for _ in range(1000):
                    pass
                assert interrupts.requested()
                reached_end = True
        assert reached_end
    finally:
        interrupts.restore()
    with interrupts.deferred():  # (not installed: nothing to raise)
        pass
