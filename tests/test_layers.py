"""The package's layers import only downwards (read from the source with ``ast``, nothing run).

Layers, lowest first: physics (``railpaper/*.py`` modules such as ``discretise``, ``track``,
``linear_gaussian``) -> ``models`` and ``estimators`` (side by side: neither imports the other) ->
``experiments`` -> ``pipeline`` -> ``cli``.  Every ``import``/``from … import`` is checked,
including the ones inside functions.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "railpaper"

#: Layer rank of each top-level part of the package; equal ranks of different parts (models,
#: estimators) may not import each other.
RANK = {"physics": 0, "models": 1, "estimators": 1, "experiments": 2, "pipeline": 3, "cli": 4,
        "__main__": 5}


def part_of(module: str) -> str | None:
    """Layer part of a dotted module name (``railpaper.models.x`` -> ``models``), None outside."""
    bits = module.split(".")
    if bits[0] != "railpaper":
        return None
    if len(bits) == 1:
        return "physics"                        # ``from railpaper import contact`` is resolved below
    return bits[1] if bits[1] in RANK else "physics"


def imported_modules(path: Path, package: str) -> list[tuple[int, str]]:
    """(line, dotted module) of every import in the file at ``path`` (module ``package``)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:                      # relative import: resolve against the package
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            found.append((node.lineno, mod))
            # ``from railpaper import models`` / ``from railpaper.pipeline import x``: the names
            # may be sub-packages or modules, so each counts as an import of mod.name
            found += [(node.lineno, f"{mod}.{alias.name}") for alias in node.names
                      if mod == "railpaper"]
    return found


def violations(package_dir: Path) -> list[str]:
    """Every upward or sideways import under ``package_dir`` (a directory named railpaper)."""
    bad = []
    for path in sorted(package_dir.rglob("*.py")):
        rel = path.relative_to(package_dir.parent).with_suffix("")
        dotted = ".".join(rel.parts)
        if rel.name == "__init__":
            dotted = ".".join(rel.parts[:-1])
        own = part_of(dotted)
        package = dotted if rel.name == "__init__" else dotted.rsplit(".", 1)[0]
        for line, mod in imported_modules(path, package):
            other = part_of(mod)
            if other is None or other == own or mod == "railpaper":
                continue
            if RANK[other] >= RANK[own]:
                bad.append(f"{path.relative_to(package_dir.parent)}:{line}: {own} imports "
                           f"{mod} ({other})")
    return bad


def test_no_upward_or_sideways_imports():
    found = violations(PACKAGE)
    assert found == [], "layer violations:\n" + "\n".join(found)


def test_the_walk_sees_every_layer():
    parts = {part_of(".".join(("railpaper",) + p.relative_to(PACKAGE).with_suffix("").parts))
             for p in PACKAGE.rglob("*.py")}
    assert {"physics", "models", "estimators", "experiments", "pipeline", "cli"} <= parts


@pytest.mark.parametrize("where, source", [
    ("models/m.py", "from railpaper.estimators.kalman import predict\n"),
    ("models/m.py", "import railpaper.experiments.base\n"),
    ("estimators/e.py", "def f():\n    from railpaper.models import lateral_16state\n"),
    ("estimators/e.py", "from railpaper import models\n"),
    ("estimators/e.py", "from ..experiments import base\n"),
    ("experiments/x.py", "from railpaper.pipeline.chapters import chapter_spec\n"),
    ("experiments/x.py", "from railpaper.cli import main\n"),
    ("discretise.py", "from railpaper.estimators.kalman import predict\n"),
    ("pipeline/p.py", "from railpaper import cli\n"),
])
def test_a_planted_violation_is_found(tmp_path, where, source):
    pkg = tmp_path / "railpaper"
    for sub in ("models", "estimators", "experiments", "pipeline"):
        (pkg / sub).mkdir(parents=True)
        (pkg / sub / "__init__.py").write_text("")
    (pkg / "__init__.py").write_text("")
    (pkg / "linear_gaussian.py").write_text("import numpy\n")
    (pkg / "models" / "ok.py").write_text("from railpaper.linear_gaussian import X\n"
                                          "from railpaper import contact\n")
    (pkg / "estimators" / "ok.py").write_text("from railpaper.estimators.kalman import predict\n"
                                              "from . import kalman\n")
    assert violations(pkg) == []
    (pkg / where).write_text(source)
    assert len(violations(pkg)) == 1


def sys_path_uses(package_dir: Path) -> list[str]:
    """Every ``sys.path`` expression in the package's source (file:line)."""
    found = []
    for path in sorted(package_dir.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            if (isinstance(node, ast.Attribute) and node.attr == "path"
                    and isinstance(node.value, ast.Name) and node.value.id == "sys"):
                found.append(f"{path.relative_to(package_dir.parent)}:{node.lineno}")
    return found


def test_the_package_never_touches_sys_path(tmp_path):
    assert sys_path_uses(PACKAGE) == []
    planted = tmp_path / "railpaper"
    planted.mkdir()
    (planted / "bench.py").write_text("import sys\n\ndef f():\n    sys.path.insert(0, '.')\n")
    assert sys_path_uses(planted) == ["railpaper/bench.py:4"]
