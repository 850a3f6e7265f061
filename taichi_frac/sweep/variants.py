"""What a sweep runs: its variants, from ``KEY=VALUES`` specs, and their stable ids.

A spec's VALUES is one of

* ``START:STOP`` or ``START:STOP:STEP``: the integers of Python's ``range`` (``0:32`` is
  0, 1, ..., 31);
* ``V1,V2,...``: a list, each value read as TOML the way ``--set`` reads it (``2e6``,
  ``true``, ``"glass"``; a list value is written ``[0,0,1]`` and is not split);
* ``LOW..HIGH``: a continuous range, only for random draws (``samples``).

Without ``samples`` a sweep runs the product of every spec's values, in the order the
specs are given (the last one varies fastest). With ``samples = N`` it runs N draws: an
integer range draws uniformly among its integers, a list among its values, ``LOW..HIGH``
uniformly between them, all from ``numpy.random.default_rng(seed)``, so a sweep seed gives
the same draws everywhere.

A variant's id is the first 12 hex digits of the SHA-256 of its settings (the varied
values, the fixed ``--set`` overrides, the frame count, the scene file's name) written as
canonical JSON: the same sweep gives the same ids, hence the same folders.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import tomllib
from dataclasses import dataclass

import numpy as np

from ..options import OptionError

#: Variants of one sweep at most (a typo like ``seed=0:1e9`` should fail, not fill a disk).
MAX_VARIANTS = 1_000_000


@dataclass(frozen=True)
class VarySpec:
    """One ``KEY=VALUES`` spec: ``values`` (a finite list) or a continuous ``low..high``.

    Attributes:
        key: the dotted scene key, as ``--set`` takes it (``ring.fracture.seed``).
        values: the values in order (ints, floats, strings, lists), or None for a range.
        low, high: the continuous range's ends (``values`` None).
        text: the spec as given (error messages).
    """

    key: str
    values: tuple | None
    low: float | None = None
    high: float | None = None
    text: str = ""

    def draw(self, rng: np.random.Generator):
        if self.values is None:
            return float(rng.uniform(self.low, self.high))
        return self.values[int(rng.integers(len(self.values)))]


@dataclass(frozen=True)
class Variant:
    """One run of a sweep.

    Attributes:
        id: 12 hex digits, a hash of everything that makes this run (see module docstring).
        index: position in the sweep (rows of sweep.csv are in this order).
        settings: the varied keys and their values, in spec order.
    """

    id: str
    index: int
    settings: dict

    def overrides(self) -> list[str]:
        """The settings as ``KEY=VALUE`` overrides (``apply_overrides``' syntax)."""
        return [f"{key}={format_value(value)}" for key, value in self.settings.items()]

    def label(self) -> str:
        """Short text for a picture: the last part of each key and its value."""
        def short(value):
            return f"{value:.4g}" if isinstance(value, float) else format_value(value)

        return ", ".join(f"{key.rsplit('.', 1)[-1]}={short(value)}" for key, value in self.settings.items())


def format_value(value) -> str:
    """A value as TOML text, which ``apply_overrides`` reads back to the same value (floats
    by ``repr``: the shortest text that round-trips)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, int):
        return str(value)
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(format_value(v) for v in value) + "]"
    raise TypeError(f"cannot write {value!r} as a scene value")


def _toml_value(text: str):
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text  # like --set: text that is not TOML is a string


def _number(text: str, spec: str):
    value = _toml_value(text.strip())
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise OptionError(f"--vary {spec!r}: {text!r} is not a number")
    return value


def parse_vary(spec: str) -> VarySpec:
    """``KEY=VALUES`` -> VarySpec; OptionError naming the spec when it is malformed."""
    if "=" not in spec:
        raise OptionError(f"--vary {spec!r} must look like KEY=VALUES, e.g. ring.fracture.seed=0:32, "
                          "ring.fracture.crack_count=1,3,5 or ring.material.tensile_strength=2e6..6e6")
    key, raw = (s.strip() for s in spec.split("=", 1))
    if not key or not raw:
        raise OptionError(f"--vary {spec!r}: give a key and values, e.g. ring.fracture.seed=0:32")
    if ".." in raw and not raw.startswith(("[", '"', "'")):
        low, _, high = raw.partition("..")
        low, high = float(_number(low, spec)), float(_number(high, spec))
        if not low < high:
            raise OptionError(f"--vary {spec!r}: the range's low end must be below its high end")
        return VarySpec(key, None, low, high, spec)
    if ":" in raw and not raw.startswith(("[", '"', "'")):
        parts = raw.split(":")
        numbers = [_number(p, spec) for p in parts] if len(parts) in (2, 3) else []
        if not numbers or not all(isinstance(n, int) for n in numbers):
            raise OptionError(f"--vary {spec!r}: an integer range is START:STOP or START:STOP:STEP "
                              "(integers; STOP excluded, like Python's range)")
        values = tuple(range(*numbers))
        if not values:
            raise OptionError(f"--vary {spec!r}: the range is empty (STOP is excluded: 0:32 is 0..31)")
        return VarySpec(key, values, text=spec)
    values = tuple(_toml_value(v.strip()) for v in _split_list(raw))
    if any(v == "" for v in values):
        raise OptionError(f"--vary {spec!r}: an empty value in the list")
    return VarySpec(key, values, text=spec)


def _split_list(raw: str) -> list[str]:
    """Split at the commas outside brackets and quotes (``[0,0,1],[0,0,2]`` is two values)."""
    parts, depth, quote, start = [], 0, None, 0
    for i, c in enumerate(raw):
        if quote:
            quote = None if c == quote else quote
        elif c in "\"'":
            quote = c
        elif c == "[":
            depth += 1
        elif c == "]":
            depth -= 1
        elif c == "," and depth == 0:
            parts.append(raw[start:i])
            start = i + 1
    parts.append(raw[start:])
    return parts


def variant_id(settings: dict, *, scene_name: str, fixed=(), frames: int | None = None) -> str:
    """The stable id: SHA-256 of the canonical JSON of everything that makes the run."""
    canonical = json.dumps({"scene": scene_name, "settings": [[k, format_value(v)] for k, v in settings.items()],
                            "fixed": list(fixed), "frames": frames}, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(canonical.encode()).hexdigest()[:12]


def make_variants(specs, *, scene_name: str, fixed=(), frames: int | None = None, samples: int | None = None,
                  seed: int = 0) -> list[Variant]:
    """The sweep's variants from ``specs`` (strings ``KEY=VALUES`` or VarySpec): their product,
    or ``samples`` random draws with ``seed``. Duplicate draws are kept once."""
    specs = [s if isinstance(s, VarySpec) else parse_vary(s) for s in specs]
    if not specs:
        raise OptionError("a sweep needs at least one --vary KEY=VALUES")
    keys = [s.key for s in specs]
    duplicated = sorted({k for k in keys if keys.count(k) > 1})
    if duplicated:
        raise OptionError(f"--vary gives {', '.join(duplicated)} more than once: give each key once with all its values")
    if samples is None:
        continuous = [s.text for s in specs if s.values is None]
        if continuous:
            raise OptionError(f"--vary {continuous[0]!r}: a LOW..HIGH range has no finite list of values; "
                              "draw from it with --samples N, or list values (V1,V2,...)")
        count = math.prod(len(s.values) for s in specs)
        if count > MAX_VARIANTS:
            raise OptionError(f"the sweep has {count:,} variants (over {MAX_VARIANTS:,}): vary fewer values")
        combos = itertools.product(*(s.values for s in specs))
    else:
        if samples < 1 or samples > MAX_VARIANTS:
            raise OptionError(f"--samples {samples}: give 1 to {MAX_VARIANTS:,}")
        rng = np.random.default_rng(seed)
        combos = ([s.draw(rng) for s in specs] for _ in range(samples))
    variants, seen = [], set()
    for values in combos:
        settings = dict(zip(keys, values))
        vid = variant_id(settings, scene_name=scene_name, fixed=fixed, frames=frames)
        if vid in seen:
            continue
        seen.add(vid)
        variants.append(Variant(vid, len(variants), settings))
    return variants
