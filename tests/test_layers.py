"""The package's architecture, read from the source with ``ast`` (nothing run).

Layers, lowest first::

    physics (railpaper/*.py: contact, track, discretise, data, stats, settling, paths, ...)
      -> engine (batched linear-Gaussian machinery)
      -> models | estimators (side by side: neither imports the other)
      -> experiments (shared parts; one package per chapter, chapters never import each other)
      -> bench -> pipeline -> cli -> __main__

Every ``import``/``from … import`` counts, including the ones inside functions; the tests below
also fail on an import cycle among ``railpaper`` modules, on an import of ``railpaper`` inside a
function outside ``cli.py`` (the usual way to hide a cycle or an upward import), on loading code
by file path (``spec_from_file_location``), on an upward import inside a chapter package, and on
an import of an engine submodule from outside the engine: ``railpaper.engine`` (its
``__init__``) is the engine's only door, so ``from railpaper.engine.rbpf import X``,
``import railpaper.engine.rbpf`` and ``from railpaper.engine import rbpf`` all fail and
``from railpaper.engine import X`` is the way.  These rules are for the package ``railpaper/``
only: the walk reads nothing else, and the tests under ``tests/engine`` import submodules on
purpose (they test the engine's internals).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "railpaper"

#: Layer rank of each top-level part of the package; equal ranks of different parts (models,
#: estimators) may not import each other.
RANK = {"physics": 0, "engine": 1, "models": 2, "estimators": 2, "experiments": 3, "bench": 4,
        "pipeline": 5, "cli": 6, "__main__": 7}

#: Order of a chapter package's modules: a module may import only modules of lower rank.  The
#: chapter's studies (every module not named here) sit between ``result`` and ``evidence``;
#: ``figures`` and ``tables`` read the result (and ``spec``, the shared ``display``), never the
#: computation.
CHAPTER_RANK = {"spec": 0, "result": 1, "evidence": 3, "experiment": 4, "tables": 5,
                "figures": 6, "__init__": 7}
STUDY_RANK = 2
#: What the drawing modules may read of their chapter: the spec and the result, never the
#: computation (a figure is redrawn from a stored result without re-running anything).
DRAWING = {"tables": {"spec", "result"}, "figures": {"spec", "result", "tables"}}


def part_of(module: str) -> str | None:
    """Layer part of a dotted module name (``railpaper.models.x`` -> ``models``), None outside."""
    bits = module.split(".")
    if bits[0] != "railpaper":
        return None
    if len(bits) == 1:
        return "physics"                        # ``from railpaper import contact`` is resolved below
    return bits[1] if bits[1] in RANK else "physics"


def module_name(path: Path, package_dir: Path) -> str:
    rel = path.relative_to(package_dir.parent).with_suffix("")
    parts = rel.parts[:-1] if rel.name == "__init__" else rel.parts
    return ".".join(parts)


def _nodes(node: ast.AST, inner: bool = False):
    """Every node below ``node`` with whether a function (or lambda) encloses it: one pass."""
    inside = inner or isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
    for child in ast.iter_child_nodes(node):
        yield child, inside
        yield from _nodes(child, inside)


def _package(path: Path, package_dir: Path) -> str:
    """Dotted name of the package a file belongs to (itself for an ``__init__``)."""
    dotted = module_name(path, package_dir)
    return dotted if path.name == "__init__.py" else dotted.rsplit(".", 1)[0]


def from_module(node: ast.ImportFrom, package: str) -> str:
    """The dotted module of ``from … import``, a relative one resolved against ``package``."""
    if not node.level:
        return node.module or ""
    base = package.split(".")[: len(package.split(".")) - node.level + 1]
    return ".".join(base + ([node.module] if node.module else []))


def imports(path: Path, package_dir: Path) -> list[tuple[int, str, bool]]:
    """(line, dotted module, inside a function) of every import in the file at ``path``."""
    tree = ast.parse(path.read_text(), filename=str(path))
    package = _package(path, package_dir)
    found = []
    for node, inner in _nodes(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name, inner) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            mod = from_module(node, package)
            found.append((node.lineno, mod, inner))
            # ``from railpaper import models`` / ``from railpaper.engine import rbpf``: a name may
            # be a sub-package or a module, so each counts as an import of mod.name as well
            found += [(node.lineno, f"{mod}.{alias.name}", inner) for alias in node.names]
    return found


def modules(package_dir: Path) -> dict[str, Path]:
    return {module_name(p, package_dir): p for p in sorted(package_dir.rglob("*.py"))}


def import_graph(package_dir: Path) -> dict[str, set[str]]:
    """Module -> the package's modules it imports (a name that is a module counts as one)."""
    known = modules(package_dir)
    graph = {}
    for name, path in known.items():
        targets = set()
        for _, mod, _ in imports(path, package_dir):
            # ``import a.b.c`` also imports a and a.b; count the deepest module that exists
            while mod and mod not in known:
                mod = mod.rsplit(".", 1)[0] if "." in mod else ""
            if mod and mod != name and not name.startswith(mod + "."):
                targets.add(mod)                # a package's own parents are imported first anyway
        graph[name] = targets
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan), each sorted."""
    index, low, on_stack, stack, out = {}, {}, set(), [], []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def chapter_of(module: str) -> tuple[str, str] | None:
    """(chapter package, module within it) for ``railpaper.experiments.<chapter>.<module>``."""
    bits = module.split(".")
    if len(bits) >= 3 and bits[:2] == ["railpaper", "experiments"]:
        return bits[2], (bits[3] if len(bits) > 3 else "__init__")
    return None


def engine_exports(package_dir: Path) -> set[str]:
    """The names the engine's ``__init__`` binds by its imports (``grid_posterior`` is both a
    submodule and the function the ``__init__`` binds over it: the function is imported)."""
    init = package_dir / "engine" / "__init__.py"
    if not init.exists():
        return set()
    return {alias.asname or alias.name for node in ast.walk(ast.parse(init.read_text()))
            if isinstance(node, ast.ImportFrom) for alias in node.names}


def engine_submodule_imports(path: Path, package_dir: Path, known: dict[str, Path],
                             exports: set[str]) -> list[tuple[int, str]]:
    """(line, engine submodule) of every import of one in the file at ``path``:
    ``import railpaper.engine.rbpf``, ``from railpaper.engine.rbpf import X`` (or relative) and
    ``from railpaper.engine import rbpf`` for a submodule the ``__init__`` does not bind over."""
    package = _package(path, package_dir)
    found = []
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            dotted = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            mod = from_module(node, package)
            dotted = [mod] if mod.startswith("railpaper.engine.") else \
                [f"{mod}.{alias.name}" for alias in node.names
                 if mod == "railpaper.engine" and f"{mod}.{alias.name}" in known
                 and alias.name not in exports]
        else:
            continue
        found += [(node.lineno, ".".join(name.split(".")[:3])) for name in dotted
                  if name.startswith("railpaper.engine.")]
    return sorted(set(found))


def violations(package_dir: Path) -> list[str]:
    """Every upward or sideways import, hidden import, engine-submodule import from outside the
    engine and path load under ``package_dir``."""
    bad = []
    known = modules(package_dir)
    chapters = {p.parent.name for p in package_dir.glob("experiments/*/__init__.py")}
    exports = engine_exports(package_dir)
    for dotted, path in known.items():
        where = path.relative_to(package_dir.parent)
        own = part_of(dotted)
        if "spec_from_file_location" in path.read_text():
            bad.append(f"{where}: loads code by file path (spec_from_file_location)")
        if own != "engine":
            bad += [f"{where}:{line}: imports the engine submodule {sub} (outside the engine, "
                    f"import from railpaper.engine)"
                    for line, sub in engine_submodule_imports(path, package_dir, known, exports)]
        for line, mod, inner in imports(path, package_dir):
            other = part_of(mod)
            if other is None or mod == "railpaper":
                continue
            if inner and own != "cli":
                bad.append(f"{where}:{line}: imports {mod} inside a function")
            if other != own and RANK[other] >= RANK[own]:
                bad.append(f"{where}:{line}: {own} imports {mod} ({other})")
            mine, theirs = chapter_of(dotted), chapter_of(mod)
            if mine and theirs and mine[0] in chapters and theirs[0] in chapters:
                if mine[0] != theirs[0]:
                    bad.append(f"{where}:{line}: chapter {mine[0]} imports chapter {theirs[0]}")
                elif theirs[1] != "__init__" and theirs[1] != mine[1]:
                    rank = CHAPTER_RANK.get(mine[1], STUDY_RANK)
                    theirs_rank = CHAPTER_RANK.get(theirs[1], STUDY_RANK)
                    drawing = mine[1] in DRAWING and theirs[1] not in DRAWING[mine[1]]
                    if drawing or theirs_rank >= rank and not rank == STUDY_RANK == theirs_rank:
                        bad.append(f"{where}:{line}: {mine[1]} imports {theirs[1]} of its "
                                   f"chapter (flow: spec <- result <- studies <- evidence <- "
                                   f"experiment; tables, figures read result and spec)")
    for component in cycles(import_graph(package_dir)):
        bad.append("import cycle: " + " -> ".join(component))
    return bad


def test_no_upward_sideways_hidden_or_circular_imports():
    found = violations(PACKAGE)
    assert found == [], "architecture violations:\n" + "\n".join(found)


def test_the_walk_sees_every_layer():
    parts = {part_of(name) for name in modules(PACKAGE)}
    assert set(RANK) <= parts


def _planted_package(tmp_path: Path) -> Path:
    pkg = tmp_path / "railpaper"
    for sub in ("engine", "models", "estimators", "experiments", "experiments/ch", "bench",
                "pipeline"):
        (pkg / sub).mkdir(parents=True)
        (pkg / sub / "__init__.py").write_text("")
    (pkg / "__init__.py").write_text("")
    (pkg / "linear.py").write_text("import numpy\n")
    (pkg / "cli.py").write_text("def main():\n    from railpaper.pipeline import ok\n")
    (pkg / "pipeline" / "ok.py").write_text("from railpaper.bench import ok\n")
    (pkg / "bench" / "ok.py").write_text("from railpaper.experiments.ch import experiment\n")
    (pkg / "engine" / "ok.py").write_text("from railpaper.linear import X\nfrom railpaper import linear\n")
    (pkg / "engine" / "__init__.py").write_text("from railpaper.engine.ok import X\n")
    (pkg / "models" / "ok.py").write_text("from railpaper.engine import X\n")
    (pkg / "estimators" / "ok.py").write_text("from . import kalman\n"
                                              "from railpaper.engine import X\n")
    (pkg / "estimators" / "kalman.py").write_text("import numpy\n")
    (pkg / "experiments" / "ch" / "spec.py").write_text("from railpaper.models import ok\n")
    (pkg / "experiments" / "ch" / "result.py").write_text("from . import spec\n")
    (pkg / "experiments" / "ch" / "toy.py").write_text("from .result import R\n")
    (pkg / "experiments" / "ch" / "walk.py").write_text("from .toy import T\n")
    (pkg / "experiments" / "ch" / "evidence.py").write_text("from .toy import T\n")
    (pkg / "experiments" / "ch" / "experiment.py").write_text("from .evidence import E\n")
    (pkg / "experiments" / "ch" / "figures.py").write_text("from .result import R\n")
    return pkg


@pytest.mark.parametrize("where, source", [
    ("models/m.py", "from railpaper.estimators.kalman import predict\n"),
    ("models/m.py", "import railpaper.experiments.base\n"),
    ("engine/e.py", "from railpaper.models import ok\n"),
    ("estimators/e.py", "from railpaper import models\n"),
    ("estimators/e.py", "from ..experiments import base\n"),
    ("experiments/x.py", "from railpaper.pipeline.chapters import chapter_spec\n"),
    ("experiments/x.py", "from railpaper.bench import ok\n"),
    ("bench/b.py", "from railpaper.pipeline import ok\n"),
    ("experiments/x.py", "from railpaper.cli import main\n"),
    ("linear2.py", "from railpaper.engine.ok import X\n"),
    ("pipeline/p.py", "from railpaper import cli\n"),
    ("engine/hidden.py", "def f():\n    from railpaper.engine import ok\n"),
    ("pipeline/load.py", "import importlib.util\nS = importlib.util.spec_from_file_location\n"),
    ("experiments/ch/toy.py", "from .evidence import E\n"),
    ("experiments/ch/result.py", "from .toy import T\n"),
    ("experiments/ch/figures.py", "from .evidence import E\n"),
    ("experiments/ch/spec.py", "from railpaper.experiments.ch.result import R\n"),
    ("models/m.py", "from railpaper.engine.ok import X\n"),
    ("estimators/e.py", "import railpaper.engine.ok\n"),
    ("experiments/x.py", "from railpaper.engine import ok\n"),
    ("bench/b.py", "from ..engine.ok import X\n"),
])
def test_a_planted_violation_is_found(tmp_path, where, source):
    pkg = _planted_package(tmp_path)
    assert violations(pkg) == []
    (pkg / where).write_text(source)
    assert len(violations(pkg)) >= 1


def test_an_engine_submodule_import_is_found(tmp_path):
    """Outside the engine only ``from railpaper.engine import X`` passes, by either import form;
    inside the engine (its ``__init__`` here) submodules are imported freely."""
    pkg = _planted_package(tmp_path)
    (pkg / "bench" / "door.py").write_text("from railpaper.engine import X\n")
    assert violations(pkg) == []
    (pkg / "bench" / "door.py").write_text("from railpaper.engine import X\n"
                                           "from railpaper.engine.ok import X, Y\n"
                                           "import railpaper.engine.ok\n")
    assert violations(pkg) == [
        f"railpaper/bench/door.py:{line}: imports the engine submodule railpaper.engine.ok "
        "(outside the engine, import from railpaper.engine)" for line in (2, 3)]


def test_a_planted_cycle_is_found(tmp_path):
    pkg = _planted_package(tmp_path)
    (pkg / "engine" / "a.py").write_text("from railpaper.engine import b\n")
    (pkg / "engine" / "b.py").write_text("from railpaper.engine.a import X\n")
    found = violations(pkg)
    assert found == ["import cycle: railpaper.engine.a -> railpaper.engine.b"]


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
