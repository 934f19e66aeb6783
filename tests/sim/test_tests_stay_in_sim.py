"""The world layer's tests run on the world layer and what sits below the tools: none of them
imports dfa_viz (the tools' tests live in tests/dfa_viz)."""

from __future__ import annotations

import ast
from pathlib import Path


def _imported(path: Path) -> set[str]:
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
    return names


def test_no_sim_test_imports_dfa_viz():
    here = Path(__file__).parent
    tests = sorted(here.glob("*.py"))
    assert len(tests) > 10
    upward = {
        p.name: sorted(n for n in _imported(p) if n.split(".")[0] == "dfa_viz") for p in tests
    }
    assert {k: v for k, v in upward.items() if v} == {}
