"""The scene-file reference (Markdown), generated from the option dataclasses themselves.

Every key of a scene file is a field of one dataclass (``scenes.loader`` maps them one to
one), so the reference reads each field's default and type from the dataclass, its meaning
and unit from the class docstring's ``Attributes:`` entry, and its allowed range from the
``check_range`` calls and ``not in CHOICES`` tests of ``__post_init__``. The documentation
site's build calls :func:`scene_file_reference` (docs/hooks.py), so the page cannot drift
from the code; a field without a docstring entry is reported by :func:`undocumented_keys`.
"""

from __future__ import annotations

import ast
import dataclasses
import inspect
import re
import sys
import textwrap

from ..options import LOOKS, MATERIAL_PRESETS, FractureOptions, Material, ParticleOptions, SimulationOptions
from .description import Collider, OutputSettings, SceneObject

# (heading, TOML location, class, keys the section leaves to another one)
SECTIONS = [
    ("Objects", "[[objects]]", SceneObject, ("particles", "fracture")),
    ("Material", "[[objects]] material = {...}", Material, ()),
    ("Particles", "[objects.particles]", ParticleOptions, ()),
    ("Fracture controls", "[objects.fracture]", FractureOptions, ()),
    ("Colliders", "[[colliders]]", Collider, ()),
    ("Simulation", "[simulation]", SimulationOptions, ()),
    ("Output", "[output]", OutputSettings, ()),
]

_UNIT = re.compile(r"\[([^\],]+)\]")


def docstring_attributes(cls) -> dict[str, str]:
    """``{field: text}`` from the ``Attributes:`` sections of the docstrings of ``cls`` and
    its bases (a field inherited from a shared options class is documented there)."""
    entries: dict[str, str] = {}
    for klass in reversed(cls.__mro__):
        entries.update(_own_attributes(inspect.cleandoc(vars(klass).get("__doc__") or "")))
    return entries


def _own_attributes(doc: str) -> dict[str, str]:
    entries: dict[str, str] = {}
    in_section, current = False, None
    for line in doc.splitlines():
        if line.strip() == "Attributes:":
            in_section = True
            continue
        if not in_section:
            continue
        if line and not line.startswith(" "):
            break  # the next section or paragraph
        match = re.match(r"^ {4}(\w+): ?(.*)$", line)
        if match:
            current = match.group(1)
            entries[current] = match.group(2).strip()
        elif current and line.strip():
            entries[current] += " " + line.strip()
        elif not line.strip():
            current = None
    return entries


def _constant(node, module_globals):
    """The value of a constant expression (numbers, arithmetic, module-level names), else None."""
    allowed = (ast.Expression, ast.Constant, ast.BinOp, ast.UnaryOp, ast.operator, ast.unaryop, ast.Name,
               ast.Load, ast.Tuple)
    if not all(isinstance(n, allowed) for n in ast.walk(ast.Expression(node))):
        return None
    try:
        return eval(compile(ast.Expression(node), "<range>", "eval"), {"__builtins__": {}}, dict(module_globals))
    except Exception:  # a name that is not a module constant
        return None


def _bound(node, module_globals) -> str:
    value = _constant(node, module_globals)
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return f"{value:,}" if isinstance(value, int) else f"{value:g}".replace("e+", "e")
    text = ast.unparse(node)
    return text.removeprefix("self.")


def _is_none(args, k) -> bool:
    """Is positional argument ``k`` absent or a literal None (an open end)?"""
    return len(args) <= k or (isinstance(args[k], ast.Constant) and args[k].value is None)


def allowed_values(cls) -> dict[str, str]:
    """``{field: "[low, high]" or "a, b, c"}`` read from the ``__post_init__`` of ``cls`` and
    of its bases (a subclass's check of a field overrides its base's)."""
    ranges: dict[str, str] = {}
    for klass in reversed(cls.__mro__):
        if "__post_init__" in vars(klass):
            ranges.update(_own_allowed_values(klass))
    return ranges


def _own_allowed_values(cls) -> dict[str, str]:
    try:
        source = textwrap.dedent(inspect.getsource(vars(cls)["__post_init__"]))
    except (OSError, TypeError, AttributeError):
        return {}
    module_globals = vars(sys.modules[cls.__module__])
    ranges: dict[str, str] = {}
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "check_range" and len(node.args) >= 3:
            name = node.args[1].value if isinstance(node.args[1], ast.Constant) else None
            if name is None:
                continue
            keywords = {k.arg: _constant(k.value, module_globals) for k in node.keywords}
            low, high = ("-inf" if _is_none(node.args, k) else _bound(node.args[k], module_globals) for k in (3, 4))
            high = "inf" if high == "-inf" else high
            if low == "-inf" and high == "inf":
                ranges.setdefault(name, "any finite number")
                continue
            ranges[name] = (("(" if keywords.get("low_open") or low == "-inf" else "[") + f"{low}, {high}"
                            + (")" if keywords.get("high_open") or high == "inf" else "]"))
        elif isinstance(node, ast.Compare) and len(node.ops) == 1 and isinstance(node.ops[0], ast.NotIn):
            target = node.left
            if isinstance(target, ast.Attribute) and isinstance(target.value, ast.Name) and target.value.id == "self":
                choices = _constant(node.comparators[0], module_globals)
                if isinstance(choices, (tuple, list, dict)):
                    ranges[target.attr] = ", ".join(f"`{c}`" for c in choices)
    return ranges


def _type_text(annotation: str) -> str:
    parts = [p.strip() for p in str(annotation).split("|")]
    optional = "None" in parts
    words = []
    for part in (p for p in parts if p != "None"):
        match = re.match(r"tuple\[(.*)\]", part)
        if match:
            words.append(f"list of {len(match.group(1).split(','))} numbers")
        else:
            words.append({"float": "number", "int": "integer", "bool": "true / false", "str": "string"}.get(
                part, f"{part} table"))
    return " or ".join(words) + (" (optional)" if optional else "")


def _default_text(item: dataclasses.Field) -> str:
    if item.default is not dataclasses.MISSING:
        value = item.default
    elif item.default_factory is not dataclasses.MISSING:
        value = item.default_factory()
        if dataclasses.is_dataclass(value):
            return "see its section"
    else:
        return "required"
    if value is None:
        return "none"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f'`"{value}"`'
    if isinstance(value, tuple):
        return "`[" + ", ".join(f"{v:g}" for v in value) + "]`"
    if isinstance(value, float):
        return f"`{value:g}`".replace("e+", "e")
    return f"`{value}`"


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def section_table(cls, skip=()) -> str:
    docs = docstring_attributes(cls)
    ranges = allowed_values(cls)
    rows = ["| key | type | default | unit | allowed | meaning |", "|---|---|---|---|---|---|"]
    for item in dataclasses.fields(cls):
        if not item.init or item.name in skip or item.name == "source_path":
            continue
        text = docs.get(item.name, "")
        unit = _UNIT.search(text)
        rows.append("| " + " | ".join(_cell(c) for c in (
            f"`{item.name}`", _type_text(item.type), _default_text(item),
            unit.group(1) if unit else "", ranges.get(item.name, ""), text)) + " |")
    return "\n".join(rows)


def _presets_table() -> str:
    rows = ["| preset | density [kg/m^3] | Young's modulus [GPa] | Poisson's ratio | tensile strength [MPa] "
            "| fracture toughness [MPa m^0.5] | fracture energy [J/m^2] | look |",
            "|---|---|---|---|---|---|---|---|"]
    for name, m in MATERIAL_PRESETS.items():
        rows.append(f"| `{name}` | {m.density:g} | {m.young_modulus / 1e9:g} | {m.poisson_ratio:g} | "
                    f"{m.tensile_strength / 1e6:g} | {m.fracture_toughness / 1e6:g} | {m.fracture_energy:.3g} | "
                    f"`{m.look}` |")
    return "\n".join(rows)


def _looks_table() -> str:
    rows = ["| look | faces | colour (linear RGB) | roughness | metallic | opacity | ior |",
            "|---|---|---|---|---|---|---|"]
    for name, look in LOOKS.items():
        for faces in ("outer", "inner"):
            s = getattr(look, faces)
            color = ", ".join(f"{c:g}" for c in s.diffuse_color)
            rows.append(f"| `{name}` | {faces} | {color} | {s.roughness:g} | {s.metallic:g} | {s.opacity:g} | "
                        f"{s.ior:g} |")
    return "\n".join(rows)


def scene_file_reference() -> str:
    """The Markdown body of the scene-file reference: one table per section."""
    parts = []
    for heading, where, cls, skip in SECTIONS:
        summary = (inspect.getdoc(cls) or "").split("\n\n")[0].replace("\n", " ")
        parts += [f"## {heading}: `{where}`", "", summary, "", section_table(cls, skip), ""]
        if cls is Material:
            parts += ["A material is a preset name (`material = \"porcelain\"`) or a table; a table with "
                      "`preset = \"...\"` starts from that preset and overrides the keys it gives. Presets:", "",
                      _presets_table(), "",
                      "Looks (render only: written into the cache as two UsdPreviewSurface materials per body, "
                      "`outer` for the original surface and `inner` for crack faces):", "", _looks_table(), ""]
    return "\n".join(parts)


def undocumented_keys() -> list[str]:
    """``section.key`` of every scene-file key without a docstring entry (should be empty)."""
    missing = []
    for _, where, cls, skip in SECTIONS:
        docs = docstring_attributes(cls)
        missing += [f"{where} {f.name}" for f in dataclasses.fields(cls)
                    if f.init and f.name not in skip and f.name != "source_path" and f.name not in docs]
    return missing
