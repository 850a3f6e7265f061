"""Writing a taichi-frac scene file (TOML) from plain data (no bpy).

Blender's Python reads TOML (``tomllib``) but cannot write it, and the add-on installs no
packages: this writer covers what a scene file holds (strings, booleans, numbers, lists of
numbers, inline tables, tables and arrays of tables) and nothing more. Floats are written
with ``repr``, so a value read back is the value written, bit for bit.
"""

from __future__ import annotations

import math
import re

_BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")


def _key(name: str) -> str:
    return name if _BARE_KEY.match(name) else _string(name)


def _string(value: str) -> str:
    escaped = value.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n").replace("\t", "\\t")
    return f'"{escaped}"'


def value_text(value) -> str:
    """One TOML value."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ValueError(f"scene value {value!r} is not finite: a scene file holds finite numbers only")
        return repr(value)
    if isinstance(value, str):
        return _string(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(value_text(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{_key(k)} = {value_text(v)}" for k, v in value.items()) + " }"
    raise TypeError(f"cannot write {type(value).__name__} {value!r} to a scene file")


def _is_table(value) -> bool:
    return isinstance(value, dict) and not getattr(value, "inline", False)


def _is_table_array(value) -> bool:
    return isinstance(value, list) and bool(value) and all(_is_table(v) for v in value)


class Inline(dict):
    """A dict written as an inline table (``material = { preset = "porcelain" }``)."""

    inline = True


def _emit(lines: list[str], table: dict, path: tuple[str, ...]) -> None:
    for key, value in table.items():
        if not (_is_table(value) or _is_table_array(value)):
            lines.append(f"{_key(key)} = {value_text(value)}")
    for key, value in table.items():
        name = ".".join(_key(p) for p in (*path, key))
        if _is_table(value):
            lines += ["", f"[{name}]"]
            _emit(lines, value, (*path, key))
        elif _is_table_array(value):
            for item in value:
                lines += ["", f"[[{name}]]"]
                _emit(lines, item, (*path, key))


def dumps(document: dict, header: str = "") -> str:
    """The TOML text of ``document`` (dicts are tables, lists of dicts arrays of tables,
    :class:`Inline` dicts inline tables), after ``header`` as comment lines."""
    lines = [f"# {line}".rstrip() for line in header.splitlines()]
    _emit(lines, document, ())
    return "\n".join(lines).lstrip("\n") + "\n"
