"""The package's shape, measured from its source (issue 30): every import between its
modules, those inside functions included, forms no cycle, and no module imports from a
layer above its own. ``python tests/test_layout.py`` prints the graph's cycles and upward
imports."""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "a2cm_phys"

COMMANDS = ("train", "evaluate", "replay", "plot", "oracle", "export", "sweep", "experiments")

LAYERS = (
    ("base", ("base",)),
    ("deploy", ("deploy",)),
    ("config", ("config",)),
    ("envs", ("envs",)),
    ("integrations", ("integrations",)),
    ("algos", ("algos",)),
    ("record", ("record",)),
    ("solve", ("solve",)),
    ("training", ("training",)),
    ("analysis", ("analysis",)),
    ("study", ("study",)),
    ("commands", ("commands", "__main__", *COMMANDS)),
)
"""Layers from the bottom up, as (name, top-level modules or packages of ``a2cm_phys``);
a module may import its own layer and those below. The package's face (``__init__``) is
above them all; the ``python -m a2cm_phys.COMMAND`` shims sit with the commands."""


def module_name(path: Path) -> str:
    """``a2cm_phys.envs.grid`` for ``a2cm_phys/envs/grid.py``."""
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def modules() -> dict[str, Path]:
    """Every module of the package by name."""
    return {module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def missing_modules() -> list[str]:
    """``file: module`` for every ``from MODULE import …`` of the package naming a module
    that does not exist (a move left behind)."""
    found = modules()
    out = []
    for name, path in found.items():
        package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and node.level:
                base = package.split(".")
                base = base[: len(base) - node.level + 1]
                stem = ".".join([*base, node.module] if node.module else base)
                if stem not in found:
                    out.append(f"{path.relative_to(PACKAGE.parent)}: {stem}")
    return out


def _type_only(tree: ast.Module) -> set[int]:
    """Ids of the import nodes under ``if TYPE_CHECKING:`` (they never run)."""
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and getattr(node.test, "id", None) == "TYPE_CHECKING":
            out |= {id(n) for stmt in node.body for n in ast.walk(stmt)}
    return out


def imports(path: Path, names: set[str]) -> set[str]:
    """The package's modules ``path`` imports, anywhere in the file (functions included;
    annotations' imports under ``if TYPE_CHECKING:`` left out: they never run)."""
    own = module_name(path)
    package = own if path.name == "__init__.py" else own.rsplit(".", 1)[0]
    out = set()
    tree = ast.parse(path.read_text(encoding="utf-8"))
    type_only = _type_only(tree)
    for node in ast.walk(tree):
        if id(node) in type_only:
            continue
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - node.level + 1]
                stem = ".".join([*base, node.module] if node.module else base)
            else:
                stem = node.module or ""
            targets = [stem] + [f"{stem}.{alias.name}" for alias in node.names]
        else:
            continue
        for target in targets:
            while target and target not in names:
                target = target.rpartition(".")[0]
            if target and target != own:
                out.add(target)
    return out


def graph() -> dict[str, set[str]]:
    """Module -> the package's modules it imports."""
    found = modules()
    names = set(found)
    return {name: imports(path, names) for name, path in found.items()}


def cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in edges.get(v, ()):
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

    sys.setrecursionlimit(10_000)
    for v in sorted(edges):
        if v not in index:
            visit(v)
    return out


def layer(name: str) -> int:
    """The layer of a module (its position in :data:`LAYERS`; above them all if unlisted)."""
    parts = name.split(".")
    top = parts[1] if len(parts) > 1 else ""
    for rank, (_, members) in enumerate(LAYERS):
        if top in members:
            return rank
    return len(LAYERS)


def upward(edges: dict[str, set[str]]) -> list[str]:
    """Imports from a lower layer to a higher one, as ``a -> b``."""
    return sorted(f"{a} -> {b}" for a, bs in edges.items() for b in bs if layer(b) > layer(a))


def test_the_import_graph_has_no_cycle():
    assert cycles(graph()) == []


def test_every_relative_import_names_a_module_that_exists():
    assert missing_modules() == []


def test_no_module_imports_from_a_layer_above_its_own():
    assert upward(graph()) == []


@pytest.mark.parametrize("case", ["cycle", "upward"])
def test_the_checks_see_what_they_look_for(tmp_path, monkeypatch, case):
    """The graph reader finds a cycle and an upward import in a package made for it,
    through relative imports inside functions."""
    package = tmp_path / "a2cm_phys"
    (package / "envs").mkdir(parents=True)
    (package / "__init__.py").write_text("")
    (package / "envs" / "__init__.py").write_text("")
    (package / "config.py").write_text("def f():\n    from .envs import grid\n")
    (package / "envs" / "grid.py").write_text(
        "from ..config import f\n" if case == "cycle" else "x = 1\n"
    )
    monkeypatch.setattr(sys.modules[__name__], "PACKAGE", package)
    edges = graph()
    assert edges["a2cm_phys.config"] == {"a2cm_phys.envs", "a2cm_phys.envs.grid"}
    if case == "cycle":
        assert cycles(edges) == [["a2cm_phys.config", "a2cm_phys.envs.grid"]]
    assert "a2cm_phys.config -> a2cm_phys.envs.grid" in upward(edges)


LIMITS = {"file": 400, "class": 150, "function": 80}
"""The largest room of each kind, in lines (issue 30)."""

KEPT_LARGE: dict[str, str] = {}
"""``path:name`` -> why it stays over its limit (its docstring says so too)."""


def oversized() -> list[str]:
    """``kind lines path[:name]`` for every file, class and function of the package over
    its limit in :data:`LIMITS`, less those in :data:`KEPT_LARGE`."""
    out = []
    for path in sorted(PACKAGE.rglob("*.py")):
        text = path.read_text(encoding="utf-8")
        where = path.relative_to(PACKAGE.parent).as_posix()
        found = [("file", len(text.splitlines()), where)]
        for node in ast.walk(ast.parse(text)):
            kind = {ast.ClassDef: "class", ast.FunctionDef: "function"}.get(type(node))
            kind = "function" if isinstance(node, ast.AsyncFunctionDef) else kind
            if kind:
                found.append((kind, node.end_lineno - node.lineno + 1, f"{where}:{node.name}"))
        out += [
            f"{kind} {lines} {name}"
            for kind, lines, name in found
            if lines > LIMITS[kind] and name not in KEPT_LARGE
        ]
    return out


def test_no_room_is_too_large_to_read():
    assert oversized() == []


RESOLVED_AT = {"a2cm_phys.commands.train", "a2cm_phys.study.runspec"}
"""Where training options enter and are resolved, once (``config.resolve_train``): the
train command, and a sweep's (or the report's) run spec."""


def resolve_calls() -> set[str]:
    """The modules outside :mod:`a2cm_phys.config` that call ``resolve_train``."""
    out = set()
    for name, path in modules().items():
        if name.startswith("a2cm_phys.config"):
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "resolve_train":
                out.add(name)
    return out


def test_the_training_config_is_resolved_once_where_options_enter():
    assert resolve_calls() == RESOLVED_AT


if __name__ == "__main__":
    g = graph()
    for c in cycles(g):
        print("cycle:", " ".join(c))
    for line in upward(g):
        print("upward:", line)
    for line in missing_modules():
        print("missing:", line)
    for line in oversized():
        print("too large:", line)


def test_the_command_shims_only_hand_over():
    """``python -m a2cm_phys.COMMAND`` files hold nothing but the hand-over to
    :mod:`a2cm_phys.commands`, and ``python -m a2cm_phys COMMAND`` reaches the same."""
    from a2cm_phys.commands import run

    for name in COMMANDS:
        text = (PACKAGE / f"{name}.py").read_text(encoding="utf-8")
        code = [line for line in text.splitlines()[1:] if line.strip()]
        assert len(code) <= 5, name
        assert f"from .commands.{name} import main" in text
    assert run(["no-such-command"]) == 2
    assert run(["replay", str(PACKAGE / "no-such-run")]) == 2
