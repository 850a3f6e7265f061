"""Scene files (TOML) -> :class:`Scene`.

Keys map one to one onto the dataclass fields of ``scenes.description`` and
``taichi_frac.options``. Unknown keys, wrong types and out-of-range values raise
``OptionError`` messages that name the file, the key path (``objects[2].particles.foo``)
and what is allowed.
"""

from __future__ import annotations

import dataclasses
import os
import tomllib
import typing
from pathlib import Path

from ..options import (
    FractureOptions,
    Material,
    MATERIAL_PRESETS,
    OptionError,
    ParticleOptions,
    SimulationOptions,
)
from .description import Collider, OutputSettings, Scene, SceneObject

# TOML value types accepted for each annotated field type (bool is not a number here).
_SCALARS = {"int": (int,), "float": (int, float), "bool": (bool,), "str": (str,)}


def _type_ok(annotation: str, value) -> bool:
    """Does TOML ``value`` fit the (string) annotation of an options field?"""
    for alt in (a.strip() for a in annotation.split("|")):
        if alt == "None":
            continue
        if alt in _SCALARS:
            if isinstance(value, bool) and alt != "bool":
                continue
            if isinstance(value, _SCALARS[alt]):
                return True
        elif alt.startswith("tuple") and isinstance(value, list):
            inner = alt[alt.index("[") + 1: -1].split(",")
            if len(value) == len(inner) and all(_type_ok(t.strip(), v) for t, v in zip(inner, value)):
                return True
        elif alt.startswith(("Material", "ParticleOptions", "FractureOptions", "list")):
            continue  # handled by the caller
    return False


def _build(cls, table, where: str, *, skip=(), extra=None):
    """Construct option dataclass ``cls`` from TOML ``table``: unknown keys and wrong types
    raise OptionError naming ``where``.key; range errors come from the class itself."""
    if not isinstance(table, dict):
        raise OptionError(f"{where} must be a table ({{...}} or [section]), got {table!r}")
    hints = {f.name: f.type if isinstance(f.type, str) else typing.get_type_hints(cls)[f.name]
             for f in dataclasses.fields(cls) if f.init}
    allowed = [k for k in hints if k not in ("source_path",)]
    kwargs = {}
    for key, value in table.items():
        if key not in allowed:
            raise OptionError(f"{where}: unknown key {key!r}; allowed keys: {', '.join(allowed)}")
        if key in skip:
            continue
        annotation = str(hints[key])
        if not _type_ok(annotation, value):
            raise OptionError(f"{where}.{key} = {value!r} has the wrong type: expected {annotation.replace('tuple', 'list')}")
        kwargs[key] = tuple(value) if isinstance(value, list) else value
    if extra:
        kwargs.update(extra)
    try:
        return cls(**kwargs)
    except OptionError as exc:
        raise OptionError(f"{where}: {exc}") from None
    except TypeError as exc:  # a missing required key
        raise OptionError(f"{where}: {exc}") from None


def _material(value, where: str) -> Material:
    """A preset name, or a table of Material fields, optionally starting from ``preset``."""
    if isinstance(value, str):
        if value not in MATERIAL_PRESETS:
            raise OptionError(f"{where} = {value!r}: unknown preset; use one of {', '.join(sorted(MATERIAL_PRESETS))} "
                              "or a table {density = ..., young_modulus = ..., poisson_ratio = ..., tensile_strength = ...}")
        return MATERIAL_PRESETS[value]
    if not isinstance(value, dict):
        raise OptionError(f"{where} must be a preset name or a table, got {value!r}")
    table = dict(value)
    preset = table.pop("preset", None)
    if preset is not None:
        base = _material(preset, f"{where}.preset")
        merged = dataclasses.asdict(base)
        merged.update(table)
        table = merged
    return _build(Material, table, where)


def _object(table, index: int, base_dir: Path | None, where_file: str) -> SceneObject:
    name = table.get("name", f"object{index}") if isinstance(table, dict) else None
    where = f"{where_file}: objects[{index}]"
    if not isinstance(table, dict):
        raise OptionError(f"{where} must be a table ([[objects]]), got {table!r}")
    if "orientation" in table and "euler_deg" in table:
        raise OptionError(f"{where}: give orientation (quaternion w,x,y,z) or euler_deg, not both")
    extra = {}
    if "material" in table:
        extra["material"] = _material(table["material"], f"{where}.material")
    if "particles" in table:
        extra["particles"] = _build(ParticleOptions, table["particles"], f"{where}.particles")
    if "fracture" in table:
        extra["fracture"] = _build(FractureOptions, table["fracture"], f"{where}.fracture")
    mesh = table.get("mesh")
    if mesh is not None and not isinstance(mesh, str):
        raise OptionError(f"{where}.mesh = {mesh!r} has the wrong type: expected a file name (string)")
    if isinstance(mesh, str):
        path = Path(mesh).expanduser()
        if not path.is_absolute() and base_dir is not None:
            path = base_dir / path
        if not path.exists():
            raise OptionError(f"{where}.mesh = {mesh!r}: file not found (looked at {str(path)!r})")
        extra["mesh"] = str(path)
    extra.setdefault("name", name)
    return _build(SceneObject, table, where, skip=("material", "particles", "fracture", "mesh"), extra=extra)


def scene_from_dict(data: dict, *, where: str = "scene", base_dir: str | os.PathLike | None = None,
                    source_path: Path | None = None) -> Scene:
    """Build a Scene from the parsed TOML structure (``where`` names it in errors)."""
    top = ("name", "objects", "colliders", "simulation", "output")
    for key in data:
        if key not in top:
            raise OptionError(f"{where}: unknown top-level key {key!r}; allowed: {', '.join(top)}")
    base = Path(base_dir) if base_dir is not None else None
    objects = data.get("objects", [])
    if not isinstance(objects, list):
        raise OptionError(f"{where}: objects must be an array of tables ([[objects]])")
    colliders = data.get("colliders", [])
    if not isinstance(colliders, list):
        raise OptionError(f"{where}: colliders must be an array of tables ([[colliders]])")
    name = data.get("name", Path(where).stem if source_path else "scene")
    if not isinstance(name, str):
        raise OptionError(f"{where}: name must be a string, got {name!r}")
    try:
        return Scene(
            name=name,
            objects=[_object(t, i, base, where) for i, t in enumerate(objects)],
            colliders=[_build(Collider, t, f"{where}: colliders[{i}]") for i, t in enumerate(colliders)],
            simulation=_build(SimulationOptions, data.get("simulation", {}), f"{where}: simulation"),
            output=_build(OutputSettings, data.get("output", {"path": f"{name}.usdc"}), f"{where}: output"),
            source_path=source_path,
        )
    except OptionError as exc:
        msg = str(exc)
        raise OptionError(msg if msg.startswith(where) else f"{where}: {msg}") from None


#: The scenes shipped with the package, loaded by name from any folder (``taichi-frac run
#: single_ring``): the paper's porcelain ring, its thirteen rings and the glass walls.
BUILTIN_SCENE_DIR = Path(__file__).resolve().parent / "builtin"


def builtin_scenes() -> list[str]:
    """Names of the built-in scenes (``single_ring``, ...), sorted."""
    return sorted(p.stem for p in BUILTIN_SCENE_DIR.glob("*.toml"))


def find_scene(scene: str | os.PathLike) -> Path:
    """The scene file ``scene`` names: a path to a TOML file, or a built-in scene's name
    (``single_ring`` or ``single_ring.toml``, no folder), found wherever the package is
    installed. A file that exists wins over a built-in name. Raises FileNotFoundError that
    lists the built-in scenes."""
    path = Path(scene)
    if path.exists():
        return path
    name = path.name.removesuffix(".toml")
    if path.parent == Path(".") and name in builtin_scenes():
        return BUILTIN_SCENE_DIR / f"{name}.toml"
    raise FileNotFoundError(f"scene file {str(scene)!r} does not exist; give a scene file (.toml) or a built-in "
                            f"scene: {', '.join(builtin_scenes())}")


def _output_in_working_folder(data: dict, default_name: str) -> dict:
    """A built-in scene's relative output path, resolved against the current folder: its
    cache belongs beside the user's work, not inside the installed package."""
    output = data.get("output", {})
    if not isinstance(output, dict):
        return data  # scene_from_dict names the bad type
    name = data.get("name", default_name)
    relative = output.get("path", f"{name}.usdc")
    if not isinstance(relative, str) or Path(relative).is_absolute():
        return data
    return {**data, "output": {**output, "path": str(Path.cwd() / relative)}}


def load_scene(path: str | os.PathLike, overrides=()) -> Scene:
    """Read a scene TOML file (a path, or a built-in scene's name: :func:`find_scene`), with
    optional ``KEY=VALUE`` overrides (see apply_overrides). A built-in scene writes its cache
    into the current folder. Raises OptionError (bad content) or FileNotFoundError."""
    path = find_scene(path)
    if path.is_dir():
        raise OptionError(f"{str(path)!r} is a folder: give a scene file (.toml) or a built-in scene: "
                          f"{', '.join(builtin_scenes())}")
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise OptionError(f"{path.name}: cannot be read: {exc.strerror or exc}") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw[:exc.start].count(b"\n") + 1
        raise OptionError(f"{path.name}: line {line}: byte 0x{raw[exc.start]:02x} is not UTF-8 text (a TOML file "
                          "must be UTF-8): save the file as UTF-8, or check it is a scene file") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise OptionError(f"{path.name}: not valid TOML: {exc}") from None
    if overrides:
        data = apply_overrides(data, overrides, where=path.name)
    if path.resolve().parent == BUILTIN_SCENE_DIR:
        data = _output_in_working_folder(data, path.stem)
    return scene_from_dict(data, where=path.name, base_dir=path.parent, source_path=path.resolve())


def apply_overrides(data: dict, overrides, *, where: str = "scene") -> dict:
    """Apply ``KEY=VALUE`` overrides to a parsed scene (returns a new dict).

    KEY is a dotted path; an object or collider is named by its ``name`` or its index, or
    ``*`` for every one, e.g. ``ring.fracture.crack_count=3``,
    ``objects.ring.material.tensile_strength=2e6``, ``objects.*.fracture.crack_fit_rounds=0``,
    ``simulation.duration=1.5``, ``colliders.0.friction=0.3``. A bare object name (or ``*``)
    stands for ``objects.NAME``. A material given as a preset name becomes ``{preset = NAME}``
    when one of its fields is overridden. VALUE is parsed as TOML (``3``, ``2e6``, ``true``,
    ``[0, 0, 1]``, ``"porcelain"``); text that is not valid TOML is taken as a string.
    VALUE ``none`` removes the key, so the option takes its default (TOML has no null:
    ``ring.fracture.crack_length=none`` lets the crack run as far as the stress says).
    """
    import copy

    data = copy.deepcopy(data)
    objects = data.get("objects", [])
    object_names = ({o.get("name") for o in objects if isinstance(o, dict) and isinstance(o.get("name"), str)}
                    if isinstance(objects, list) else set())
    for item in overrides:
        if "=" not in item:
            raise OptionError(f"{where}: override {item!r} must look like KEY=VALUE, e.g. ring.fracture.crack_count=3")
        key, raw = (s.strip() for s in item.split("=", 1))
        try:
            value = tomllib.loads(f"v = {raw}")["v"]
        except tomllib.TOMLDecodeError:
            value = raw
        parts = key.split(".")
        if (parts[0] in object_names or parts[0] == "*") and parts[0] not in ("objects", "colliders", "simulation",
                                                                            "output", "name"):
            parts = ["objects"] + parts
        _apply_override(data, parts, 0, None if raw.lower() == "none" else value, key, where, object_names)
    return data


def _apply_override(node, parts: list, depth: int, value, key: str, where: str, object_names) -> None:
    """Set ``parts[depth:]`` under ``node`` (the scene's table at ``parts[:depth]``) to
    ``value`` (None: remove the key); ``*`` in a list sets it in every entry."""
    for depth in range(depth, len(parts) - 1):
        part = parts[depth]
        here = ".".join(parts[:depth]) or "scene"
        if isinstance(node, list):
            if part == "*":
                entries = [t for t in node if isinstance(t, dict)]
                if not entries:
                    raise OptionError(f"{where}: override {key!r}: {here} has no entries for '*' to set")
                for entry in entries:
                    _apply_override(entry, parts, depth + 1, value, key, where, object_names)
                return
            match = [t for t in node if isinstance(t, dict) and t.get("name") == part]
            if match:
                node = match[0]
            elif part.isascii() and part.isdigit() and int(part) < len(node):
                node = node[int(part)]
            else:
                raise OptionError(f"{where}: override {key!r}: no entry named {part!r} in {here}")
            continue
        child = node.get(part)
        if child is None:
            # A table the scene leaves out takes its defaults; set one of its keys.
            child = node[part] = {} if depth > 0 or part in ("simulation", "output") else None
            if child is None and part in ("objects", "colliders"):
                raise OptionError(f"{where}: override {key!r}: the scene has no {part}")
            if child is None:
                names = ", ".join(sorted(str(n) for n in object_names)) or "none"
                raise OptionError(f"{where}: override {key!r}: unknown key {part!r}; a key starts with "
                                  f"simulation, output, objects, colliders or an object's name ({names})")
        elif isinstance(child, str) and part == "material":
            child = node[part] = {"preset": child}
        elif not isinstance(child, (dict, list)):
            raise OptionError(f"{where}: override {key!r}: {here}.{part} is a value, not a table")
        node = child
    if isinstance(node, list):
        raise OptionError(f"{where}: override {key!r} names a list; add the entry's name or index, or '*'")
    if value is None:
        node.pop(parts[-1], None)
    else:
        node[parts[-1]] = value
