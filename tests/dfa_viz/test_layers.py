"""The shape of dfa_viz: a core (the loop, users, configs, the recording) that loads no client
(the page, the sweep, the experiments, the study, the bench, the LeRobot commands), no import
circle at module level, and no private name borrowed across a client's border."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import dfa_viz

CLIENTS = ("app", "sweep", "experiment", "study", "bench", "lerobot", "cli", "assemble")
CLIENT_PARTS = [[c] for c in CLIENTS]
ROOT = Path(dfa_viz.__file__).parent


def _module(path: Path) -> str:
    parts = path.relative_to(ROOT.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(path: Path, name: str, nodes) -> list[tuple[str, list[str]]]:
    """(module, names) of each import among `nodes` of `path` (module `name`), relative
    imports resolved; `import a.b` is ("a.b", [])."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out: list[tuple[str, list[str]]] = []
    for node in nodes:
        if isinstance(node, ast.Import):
            out += [(a.name, []) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*up, *([base] if base else [])])
            out.append((base, [a.name for a in node.names]))
    return out


def _dfa_viz_modules(imports: list[tuple[str, list[str]]]) -> set[str]:
    """The dfa_viz modules (or names in them) the imports name."""
    out = {m for m, _ in imports} | {f"{m}.{n}" for m, names in imports for n in names}
    return {m for m in out if m.split(".")[0] == "dfa_viz"}


def _top_level_imports(path: Path, name: str) -> set[str]:
    """The dfa_viz modules `path` imports when it is imported (not inside functions, not
    under `if TYPE_CHECKING:`)."""
    return _dfa_viz_modules(_imports(path, name, ast.parse(path.read_text()).body))


def _graph() -> dict[str, set[str]]:
    paths = {_module(p): p for p in ROOT.rglob("*.py")}
    graph = {}
    for name, path in paths.items():
        targets = set()
        for m in _top_level_imports(path, name):
            if m in paths:
                targets.add(m)
            parts = m.split(".")  # importing a.b.c runs a and a.b first
            targets |= {".".join(parts[:k]) for k in range(1, len(parts))} & set(paths)
        graph[name] = targets - {name}
    return graph


def test_no_import_circle_at_module_level():
    graph = _graph()
    state: dict[str, int] = {}
    circles = []

    def visit(node: str, path: list[str]) -> None:
        state[node] = 1
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                circles.append([*path[path.index(nxt) :], nxt])
            elif nxt not in state:
                visit(nxt, [*path, nxt])
        state[node] = 2

    for node in sorted(graph):
        if node not in state:
            visit(node, [node])
    # a package's __init__ importing its own modules is how a package is made, not a circle
    real = [c for c in circles if not all(m.startswith(c[0]) or c[0].startswith(m) for m in c)]
    assert real == [], real


def _core() -> dict[str, Path]:
    """The core's modules: every dfa_viz module outside the clients."""
    paths = {_module(p): p for p in ROOT.rglob("*.py")}
    return {n: p for n, p in paths.items() if n != "dfa_viz" and n.split(".")[1] not in CLIENTS}


def _every_import(path: Path, name: str) -> set[str]:
    """The dfa_viz modules `path` names in any import: at module level, inside functions and
    under `if TYPE_CHECKING:`."""
    return _dfa_viz_modules(_imports(path, name, ast.walk(ast.parse(path.read_text()))))


def test_the_core_names_no_client_in_any_import():
    core = _core()
    assert {"dfa_viz.loop", "dfa_viz.configs", "dfa_viz.recording", "dfa_viz.users"} <= set(core)
    reached = {
        name: sorted(m for m in _every_import(path, name) if m.split(".")[1:2] in CLIENT_PARTS)
        for name, path in core.items()
    }
    assert {n: m for n, m in reached.items() if m} == {}


def test_importing_the_core_loads_no_client():
    code = (
        f"import sys; [__import__(m) for m in {sorted(_core())!r}]; "
        f"print(sorted(m for m in sys.modules if m.split('.')[1:2] and "
        f"m.split('.')[0] == 'dfa_viz' and m.split('.')[1] in {CLIENTS!r}))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]", out.stdout


def _unit(module: str) -> str:
    """The client a dfa_viz module belongs to, or "core"."""
    part = module.split(".")[1:2]
    return part[0] if part in CLIENT_PARTS else "core"


def test_no_module_imports_a_private_name_from_another_client_or_the_core():
    borrowed = []
    for p in ROOT.rglob("*.py"):
        name = _module(p)
        for base, names in _imports(p, name, ast.walk(ast.parse(p.read_text()))):
            if base.split(".")[0] != "dfa_viz" or _unit(base) != _unit(name):
                borrowed += [f"{name} <- {base}.{n}" for n in names if n.startswith("_")]
    assert borrowed == []
