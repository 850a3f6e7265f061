"""Which part of a cache goes into the scene, and when: frame range, retiming to the scene's
frame rate, and which pieces are ever seen. Pure numpy (no bpy, no pxr): tests run it in plain
Python.

Time is kept, not frame numbers: cache frame ``c`` (time ``c / cache_fps`` seconds) lands on
scene frame ``frame_offset + c * scene_fps / cache_fps``. A 50 fps cache in a 24 fps scene
gets keys on fractional frames; Blender interpolates between them, so every scene frame shows
the pose of its own instant.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ImportOptions:
    """What the importer does with a cache (the operator's settings).

    set_scene_settings: set the scene's frame rate to the cache's and its frame range to the
        imported frames (otherwise keys are retimed to the scene's frame rate).
    frame_offset: scene frame [frames] where the cache's time 0 lands.
    frame_first, frame_last: cache frames imported (None: the cache's start / end).
    skip_never_visible: leave out pieces visible at no scene frame of the range (born and
        broken between two frames).
    missing: what re-import does to pieces it made before that the cache no longer has
        (or that are now skipped): "REMOVE" them or "HIDE" them.
    update_existing: re-import into the collection already made from the same file.
    """

    set_scene_settings: bool = True
    frame_offset: float = 0.0
    frame_first: float | None = None
    frame_last: float | None = None
    skip_never_visible: bool = True
    missing: str = "REMOVE"
    update_existing: bool = True

    def __post_init__(self):
        if self.missing not in ("REMOVE", "HIDE"):
            raise ValueError(f"missing must be 'REMOVE' or 'HIDE', got {self.missing!r}")
        if self.frame_first is not None and self.frame_last is not None and self.frame_first > self.frame_last:
            raise ValueError(f"frame range {self.frame_first}-{self.frame_last} is empty: first must be <= last")


@dataclass(frozen=True)
class Timing:
    """Cache frames [first, last] mapped onto scene frames."""

    cache_fps: float
    scene_fps: float
    frame_offset: float
    first: float   # cache frames
    last: float

    @property
    def scale(self) -> float:
        """Scene frames per cache frame."""
        return self.scene_fps / self.cache_fps

    def to_scene(self, cache_frames):
        # (rounded to 1e-6 frame: 25 * 24/50 is 12.000000000000002 in floating point, and a key
        # meant for frame 12 must not miss it)
        return np.round(self.frame_offset + np.asarray(cache_frames, dtype=np.float64) * self.scale, 6)

    def scene_range(self) -> tuple[int, int]:
        """The whole scene frames the imported range covers."""
        lo, hi = self.to_scene([self.first, self.last])
        return int(np.ceil(lo - 1e-9)), int(np.floor(hi + 1e-9))


def make_timing(cache, scene_fps: float, options: ImportOptions) -> Timing:
    """The mapping for ``cache`` (reader.CacheData) into a scene at ``scene_fps``; the range
    is clipped to the frames the cache holds (an incomplete cache: up to its last frame)."""
    end = cache.end_frame
    if cache.complete is False and cache.last_frame is not None:
        end = min(end, float(cache.last_frame))
    first = cache.start_frame if options.frame_first is None else max(float(options.frame_first), cache.start_frame)
    last = end if options.frame_last is None else min(float(options.frame_last), end)
    if first > last:
        raise ValueError(f"frames {options.frame_first}-{options.frame_last} are outside the cache's "
                         f"{cache.start_frame:g}-{end:g}")
    return Timing(cache_fps=float(cache.fps), scene_fps=float(scene_fps), frame_offset=float(options.frame_offset),
                  first=first, last=last)


def _slerp(q0: np.ndarray, q1: np.ndarray, t: float) -> np.ndarray:
    """Spherical interpolation of unit quaternions (what USD does between orient samples)."""
    if np.dot(q0, q1) < 0.0:
        q1 = -q1
    angle = np.arccos(np.clip(np.dot(q0, q1), -1.0, 1.0))
    if angle < 1e-9:
        q = q0 + t * (q1 - q0)
    else:
        q = (np.sin((1.0 - t) * angle) * q0 + np.sin(t * angle) * q1) / np.sin(angle)
    return q / np.linalg.norm(q)


def pose_at(frames: np.ndarray, positions: np.ndarray, orientations: np.ndarray, frame: float):
    """The pose USD gives at ``frame``: linear translate, slerped orient, held outside the
    samples. frames (S,), positions (S,3), orientations (S,4) (w,x,y,z)."""
    k = int(np.searchsorted(frames, frame, side="right"))
    if k == 0:
        return positions[0], orientations[0]
    if k == len(frames) or frames[k - 1] == frame:
        return positions[k - 1], orientations[k - 1]
    t = (frame - frames[k - 1]) / (frames[k] - frames[k - 1])
    return (positions[k - 1] + t * (positions[k] - positions[k - 1]),
            _slerp(orientations[k - 1], orientations[k], t))


def clip_poses(frames: np.ndarray, positions: np.ndarray, orientations: np.ndarray, first: float, last: float):
    """The pose samples inside [first, last], with the pose at ``first`` and at ``last`` added
    where no sample falls there (so the keys read as the cache does across the whole range)."""
    if first == last:
        p, q = pose_at(frames, positions, orientations, first)
        return np.array([first]), p[None], q[None]
    inside = (frames >= first) & (frames <= last)
    out_f, out_p, out_q = [frames[inside]], [positions[inside]], [orientations[inside]]
    for edge, where in ((first, 0), (last, 1)):
        if edge in frames:
            continue
        p, q = pose_at(frames, positions, orientations, edge)
        index = 0 if where == 0 else len(out_f)
        out_f.insert(index, np.array([edge]))
        out_p.insert(index, p[None])
        out_q.insert(index, q[None])
    f = np.concatenate(out_f)
    p = np.concatenate(out_p)
    q = np.concatenate(out_q)
    if len(q) > 1:  # sign-continuous again after slerped ends
        step = np.sign(np.einsum("ij,ij->i", q[1:], q[:-1]))
        step[step == 0] = 1.0
        q = q * np.concatenate([[1.0], np.cumprod(step)])[:, None]
    if np.all(p == p[0]) and np.all(q == q[0]):  # still over the whole range: one pose
        return f[:1], p[:1], q[:1]
    return f, p, q


def clip_visibility(frames: np.ndarray, visible: np.ndarray, first: float, last: float):
    """Visibility keys (held from each key to the next) inside [first, last], starting with
    the value at ``first``; consecutive equal values merged."""
    k = max(int(np.searchsorted(frames, first, side="right")) - 1, 0)
    keep = (frames > first) & (frames <= last)
    f = np.concatenate([[first], frames[keep]])
    v = np.concatenate([[visible[k]], visible[keep]]).astype(bool)
    changes = np.concatenate([[True], v[1:] != v[:-1]])
    return f[changes], v[changes]


def shown_at_some_frame(scene_frames: np.ndarray, visible: np.ndarray, lo: int, hi: int) -> bool:
    """Whether keys held from each scene frame in ``scene_frames`` to the next make the object
    visible at any whole frame in [lo, hi] (what Blender shows and renders)."""
    ends = np.concatenate([scene_frames[1:], [np.inf]])
    for start, end, shown in zip(scene_frames, ends, visible):
        if not shown:
            continue
        n = max(np.ceil(start - 1e-9), lo)
        if n <= hi and n < end - 1e-9:
            return True
    return False
