"""The package's import layers (docs/ARCHITECTURE.md): every relative import inside
``taichi_frac`` goes down the list of layers or stays in its own layer, and no module
imports the test suite. Checked on the source text (ast), so a lazy import inside a
function counts too."""

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "taichi_frac"

#: (module prefix, layer): 0 is the top; the longest matching prefix decides.
LAYERS = [
    ("cli", 0), ("__main__", 0), ("commands", 0), ("sweep", 0),
    ("simulation", 1),
    ("io", 2), ("scene_setup", 2),
    ("surfaces", 3),
    ("scenes", 4),
    ("fracture", 5),
    ("dynamics", 6),
    ("collision", 7),
    ("model", 8), ("geometry", 8),
    ("kinematics", 9), ("options", 9), ("runtime", 9), ("interrupts", 9), ("blas", 9), ("memo", 9),
]


def layer(module: str) -> int | None:
    best = None
    for prefix, level in LAYERS:
        if (module == prefix or module.startswith(prefix + ".")) and (best is None or len(prefix) > len(best[0])):
            best = (prefix, level)
    return None if best is None else best[1]


def imports(path: Path):
    """(imported module, line) of every import in ``path``, relative ones resolved
    against the package (``from .x import y`` -> ``x.y``: y may be a module)."""
    parts = list(path.relative_to(PACKAGE).with_suffix("").parts)
    package = parts[:-1] if parts[-1] != "__init__" else parts[:-1]
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            if node.level == 0:
                yield (node.module or ""), node.lineno
                continue
            base = package[: len(package) - (node.level - 1)]
            module = base + (node.module.split(".") if node.module else [])
            for alias in node.names:
                yield ".".join(module + [alias.name]), node.lineno
        elif isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name, node.lineno


def test_layer_lookup_by_longest_prefix():
    assert layer("fracture.stage") == 5 and layer("surfaces.cut") == 3
    assert layer("geometry.prepare") == 8 and layer("kinematics.quaternion.quat_mul") == 9
    assert layer("numpy") is None


def test_no_module_imports_a_layer_above_its_own():
    upward = []
    for path in sorted(PACKAGE.rglob("*.py")):
        own = ".".join(path.relative_to(PACKAGE).with_suffix("").parts).removesuffix(".__init__")
        mine = layer(own)
        if mine is None or own.endswith("__init__"):
            continue
        for module, line in imports(path):
            theirs = layer(module)
            if theirs is not None and theirs < mine:
                upward.append(f"{path.relative_to(PACKAGE.parent)}:{line} imports {module}")
    assert not upward, "imports against the layers of docs/ARCHITECTURE.md:\n" + "\n".join(upward)


def test_the_package_never_imports_the_tests_or_the_benchmarks():
    """The benchmarks are not installed with the package: only ``taichi-frac bench`` (the
    checkout's gateway, commands/bench.py) reaches into them, after finding the checkout."""
    gateway = PACKAGE / "commands" / "bench.py"
    found = [f"{path.relative_to(PACKAGE.parent)}:{line} imports {module}"
             for path in sorted(PACKAGE.rglob("*.py")) for module, line in imports(path)
             if (module.split(".")[0] in ("tests", "support", "conftest") or module.startswith("test_")
                 or (module.split(".")[0] == "benchmarks" and path != gateway))]
    text_hits = [str(path.relative_to(PACKAGE.parent)) for path in PACKAGE.rglob("*.py")
                 if "sys.path" in path.read_text() and "tests" in path.read_text()]
    assert not found and not text_hits, found + text_hits
