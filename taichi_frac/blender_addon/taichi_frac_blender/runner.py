"""``taichi-frac run`` in its own process, watched from Blender (no bpy here).

The simulator never runs inside Blender: a crash, a runaway allocation or a long compile
stays in the child process. :class:`SimulationRun` starts the command with
``--progress-json`` (one JSON object a frame on stderr), reads its output on two threads so
that neither pipe fills and blocks the child, and offers what a modal operator needs:
``progress`` (read between events), ``cancel`` (SIGINT: the command keeps a valid cache of
the frames done) and ``error_line`` (the command's one-line error, or a short reason).
"""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import signal
import subprocess
import threading
from dataclasses import dataclass

EXECUTABLE_ENV = "TAICHI_FRAC_EXECUTABLE"
COMMAND = "taichi-frac"


class RunError(Exception):
    """The simulation could not be started, or it failed: one line for the status bar."""


def find_executable(preference: str = "", environ=None) -> tuple[str, str]:
    """(path of the taichi-frac command, where it was found): the add-on's preference first,
    then the ``TAICHI_FRAC_EXECUTABLE`` environment variable, then the PATH. Raises RunError
    naming where to set it when none gives an executable file."""
    environ = os.environ if environ is None else environ
    for value, where in ((preference, "the add-on's preferences"), (environ.get(EXECUTABLE_ENV, ""), EXECUTABLE_ENV)):
        if not value:
            continue
        path = os.path.expanduser(value)
        if os.path.isfile(path) and os.access(path, os.X_OK):
            return path, where
        found = shutil.which(path)  # (a bare command name)
        if found:
            return found, where
        raise RunError(f"the taichi-frac executable {value!r} from {where} does not exist or is not executable: "
                       "point it at the taichi-frac command of the environment where taichi-frac is installed "
                       "(e.g. .venv/bin/taichi-frac)")
    found = shutil.which(COMMAND, path=environ.get("PATH"))
    if found:
        return found, "PATH"
    raise RunError(f"the {COMMAND} command was not found: set its path in the add-on's preferences "
                   f"(Edit > Preferences > Add-ons > taichi-frac), or in the {EXECUTABLE_ENV} environment "
                   f"variable, or install taichi-frac where the PATH finds it")


@dataclass
class Progress:
    """The latest frame the run reported: frame done, frame count, simulated time [s], live
    fragments, frames per second of wall time; once the frames are done and the run waits for
    the last pieces' surfaces, how many of the splits it waits for are left (-1: not waiting)."""

    frame: int = 0
    frames: int = 0
    time: float = 0.0
    fragments: int = 0
    fps: float = 0.0
    surfaces_left: int = -1
    surfaces_splits: int = 0

    @property
    def fraction(self) -> float:
        return self.frame / self.frames if self.frames else 0.0


def parse_surfaces_wait(line: str) -> tuple[int, int] | None:
    """A ``{"stage": "surfaces", "left", "splits"}`` line as (left, splits), else None."""
    line = line.strip()
    if not line.startswith('{"stage": "surfaces"'):
        return None
    try:
        data = json.loads(line)
        return int(data["left"]), int(data["splits"])
    except (ValueError, KeyError, TypeError):
        return None


def parse_progress(line: str) -> Progress | None:
    """A ``--progress-json`` line as Progress, or None for any other line."""
    line = line.strip()
    if not line.startswith('{"frame"'):
        return None
    try:
        data = json.loads(line)
        return Progress(frame=int(data["frame"]), frames=int(data["frames"]), time=float(data["time"]),
                        fragments=int(data["fragments"]), fps=float(data.get("fps", 0.0)))
    except (ValueError, KeyError, TypeError):
        return None


class SimulationRun:
    """One ``taichi-frac run SCENE --progress-json --stats-json STATS`` in a child process.

    The child runs apart from Blender's terminal (``start_new_session``): a Ctrl-C typed in
    the terminal that started Blender does not reach it; only :meth:`cancel` stops it.
    """

    def __init__(self, executable: str, scene_path: str, stats_path: str | None = None, extra_args=()):
        self.command = [executable, "run", scene_path, "--progress-json"]
        if stats_path:
            self.command += ["--stats-json", stats_path]
        self.command += list(extra_args)
        self.process: subprocess.Popen | None = None
        self.progress = Progress()
        self.stdout_lines: list[str] = []
        self.stderr_lines: list[str] = []
        self.cancelled = False
        self._threads: list[threading.Thread] = []
        self._lock = threading.Lock()

    def start(self) -> None:
        env = dict(os.environ)
        # Blender's own Python must not leak into the child's (a bpy wheel's venv, Blender's
        # bundled site-packages): the command's environment is its own.
        for key in ("PYTHONPATH", "PYTHONHOME", "PYTHONNOUSERSITE"):
            env.pop(key, None)
        # A fixed string hash: Taichi's offline kernel cache then finds the kernels of a scene
        # run before (with two breakable bodies, randomised hashing misses it every run and
        # the command compiles its kernels again: about 9 s on two cores).
        env.setdefault("PYTHONHASHSEED", "0")
        try:
            self.process = subprocess.Popen(
                self.command, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                bufsize=1, env=env, start_new_session=(os.name == "posix"),
                creationflags=getattr(subprocess, "CREATE_NEW_PROCESS_GROUP", 0) if os.name == "nt" else 0)
        except OSError as exc:
            raise RunError(f"could not start {self.command[0]}: {exc.strerror or exc}") from None
        for stream, sink in ((self.process.stdout, self.stdout_lines), (self.process.stderr, self.stderr_lines)):
            thread = threading.Thread(target=self._read, args=(stream, sink), daemon=True)
            thread.start()
            self._threads.append(thread)

    def _read(self, stream, sink: list[str]) -> None:
        for line in stream:
            progress = parse_progress(line)
            waiting = None if progress is not None else parse_surfaces_wait(line)
            with self._lock:
                if progress is not None:
                    self.progress = progress
                elif waiting is not None:
                    self.progress = dataclasses.replace(self.progress, surfaces_left=waiting[0],
                                                        surfaces_splits=waiting[1])
                else:
                    sink.append(line.rstrip("\n"))

    def poll(self) -> int | None:
        """The exit status once the child has ended and its output is read, else None."""
        code = self.process.poll()
        if code is None:
            return None
        for thread in self._threads:
            thread.join(timeout=5.0)
        return code

    def wait(self, timeout: float | None = None) -> int:
        """Block until the child ends; its exit status."""
        self.process.wait(timeout=timeout)
        return self.poll()

    def cancel(self) -> None:
        """Ask the run to stop: SIGINT, which the command honours between steps and answers
        by closing a valid cache of the frames done (exit status 130). On Windows a
        Ctrl-Break, which ends the command: its cache keeps its last checkpoint."""
        if self.process is None or self.process.poll() is not None or self.cancelled:
            return  # (a second SIGINT would end the command at once, losing the frames since its checkpoint)
        self.cancelled = True
        if os.name == "nt":
            self.process.send_signal(signal.CTRL_BREAK_EVENT)
        else:
            self.process.send_signal(signal.SIGINT)

    def kill(self) -> None:
        """End the child at once (its cache keeps its last checkpoint)."""
        if self.process is not None and self.process.poll() is None:
            self.process.kill()

    def error_line(self) -> str:
        """The command's own one-line error (what follows ``taichi-frac run: error:``), else
        the last line it printed, else its exit status."""
        with self._lock:
            lines = [line.strip() for line in self.stderr_lines if line.strip()]
        for line in reversed(lines):
            if line.startswith(f"{COMMAND} run:"):
                line = line[len(f"{COMMAND} run:"):].strip()
                return line[len("error:"):].strip() if line.startswith("error:") else line
        if lines:
            return lines[-1]
        code = None if self.process is None else self.process.returncode
        return f"{COMMAND} run exited with status {code} and printed nothing"

    def summary_text(self) -> str:
        with self._lock:
            return "\n".join(self.stdout_lines)

