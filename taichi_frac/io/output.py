"""Where a run writes: checked before any work, and held by one run at a time.

:func:`check_output_path` and :func:`check_stats_path` refuse, before a scene is meshed,
what would otherwise fail only after the whole simulation: a folder, a wrong suffix, a
folder that is missing or not writable. :class:`OutputLock` is a lock file beside the cache
(``.NAME.lock``, holding the owner's process id and host) so a second run on the same
output refuses to start instead of overwriting the first's file; a lock whose process is
gone (a killed run) is taken over.
"""

from __future__ import annotations

import os
import socket
from pathlib import Path

from ..options import OptionError

CACHE_SUFFIXES = (".usdc", ".usda", ".usd")


class OutputError(OptionError):
    """An output path that cannot be written, or that another run holds."""


def _check_folder(path: Path, what: str) -> None:
    folder = path.parent if str(path.parent) else Path(".")
    existing = folder
    while not existing.exists():  # the cache writer creates missing folders
        existing = existing.parent
    if not existing.is_dir():
        raise OutputError(f"{what} {str(path)!r}: {str(existing)!r} is a file, not a folder")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise OutputError(f"{what} {str(path)!r}: the folder {str(existing)!r} is not writable; choose another "
                          "path or fix its permissions")
    if path.is_dir():
        raise OutputError(f"{what} {str(path)!r} is a folder: give a file name inside it")
    if path.exists() and not os.access(path, os.W_OK):
        raise OutputError(f"{what} {str(path)!r} exists and is not writable")


def check_output_path(path) -> Path:
    """The cache path, refused (OutputError) unless it is a .usdc/.usda/.usd file that can
    be written; its folder may be missing (it is created)."""
    path = Path(path)
    if path.is_dir():
        raise OutputError(f"output {str(path)!r} is a folder: give a file name inside it, e.g. "
                          f"{str(path / 'shot.usdc')!r}")
    if path.suffix.lower() not in CACHE_SUFFIXES:
        raise OutputError(f"output {str(path)!r}: a cache must end in .usdc (binary), .usda (text) or .usd, "
                          f"not {path.suffix or 'no suffix'!r}")
    _check_folder(path, "output")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"output {str(path)!r}: cannot create its folder: {exc.strerror or exc}") from None
    return path


def check_stats_path(path) -> Path:
    """The ``--stats-json`` file, refused (OutputError) unless its folder exists and it can
    be written (a missing folder is a typo more often than a wish)."""
    path = Path(path)
    if not path.parent.is_dir():
        raise OutputError(f"--stats-json {str(path)!r}: the folder {str(path.parent)!r} does not exist")
    _check_folder(path, "--stats-json")
    return path


def _process_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's process: alive
        return True
    # A killed run whose parent died too can linger as a zombie until init reaps it (some
    # containers' init never does); it answers signal 0 but will never write again.
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return True  # no /proc (macOS): signal 0 is all there is
    return stat.rpartition(")")[2].split()[:1] not in (["Z"], ["X"])


class OutputLock:
    """A lock file beside ``path``: only one run writes a cache at a time.

    ``acquire(overwrite=False)`` raises OutputError when another live process holds it
    (``overwrite`` takes it over: that run stops at its next write, see :meth:`check`).
    """

    def __init__(self, path):
        self.path = Path(path)
        self.lock_path = self.path.with_name(f".{self.path.name}.lock")
        self.owner = f"{os.getpid()} {socket.gethostname()}"
        self.held = False

    def holder(self) -> str | None:
        """The lock file's 'pid host', or None when there is none."""
        try:
            return self.lock_path.read_text().strip() or None
        except (FileNotFoundError, IsADirectoryError):
            return None

    def _stale(self, holder: str) -> bool:
        pid, _, host = holder.partition(" ")
        if holder == self.owner:
            return True  # this process (a Simulation built again on the same output)
        return host == socket.gethostname() and pid.isdigit() and not _process_alive(int(pid))

    def acquire(self, *, overwrite: bool = False) -> None:
        holder = self.holder()
        if holder is not None and not overwrite and not self._stale(holder):
            pid, _, host = holder.partition(" ")
            raise OutputError(f"output {str(self.path)!r} is being written by another run (process {pid} on {host}; "
                              f"lock {str(self.lock_path)!r}): wait for it, choose another -o, or pass --overwrite")
        tmp = self.lock_path.with_name(f"{self.lock_path.name}.{os.getpid()}")
        try:  # (also the test that the folder is writable: permissions can say yes to root)
            self.lock_path.parent.mkdir(parents=True, exist_ok=True)
            tmp.write_text(self.owner + "\n")
            os.replace(tmp, self.lock_path)
        except OSError as exc:
            raise OutputError(f"output {str(self.path)!r}: cannot write in its folder: {exc.strerror or exc}") from None
        self.held = True

    def check(self) -> None:
        """Raise OutputError if another run has taken the lock over since ``acquire``."""
        if not self.held:
            return
        holder = self.holder()
        if holder != self.owner:
            self.held = False
            raise OutputError(f"output {str(self.path)!r} was taken over by another run ({holder or 'lock removed'}); "
                              "this run stops without writing it")

    def release(self) -> None:
        if self.held and self.holder() == self.owner:
            self.lock_path.unlink(missing_ok=True)
        self.held = False
