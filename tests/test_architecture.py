"""The package's shape (issue 12): no import cycles, short modules and functions, no private imports."""

import ast
from pathlib import Path

import pytest

from irdic.codehash import module_imports

PKG = Path(__file__).resolve().parents[1] / "irdic"
FILES = sorted(PKG.rglob("*.py"))

#: functions allowed over 80 lines, with the reason (at most three in the package)
LONG_FUNCTIONS_ALLOWED: dict[str, str] = {}


def _name(f: Path) -> str:
    parts = [p for p in f.relative_to(PKG).with_suffix("").parts if p != "__init__"]
    return ".".join(["irdic", *parts])


def _graph() -> dict[str, set[str]]:
    """Module -> the irdic modules it imports (lazy imports inside functions included, packages excluded).

    A package's ``__init__`` runs before its modules but is not imported by
    them in a cycle sense, so parents are left out here.
    """
    graph = {}
    for f in FILES:
        me = _name(f)
        deps = {d for d in module_imports(f, PKG) if d != me and not me.startswith(d + ".")}
        graph[me] = deps
    return graph


def _cycle(graph):
    """One import cycle as a list of modules, or None."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(n):
        state[n] = 1
        stack.append(n)
        for m in sorted(graph.get(n, ())):
            if state.get(m) == 1:
                return stack[stack.index(m):] + [m]
            if m not in state:
                found = visit(m)
                if found:
                    return found
        stack.pop()
        state[n] = 2
        return None

    for n in sorted(graph):
        if n not in state:
            found = visit(n)
            if found:
                return found
    return None


def test_the_cycle_finder_finds_a_cycle():
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _cycle({"a": {"b"}, "b": set()}) is None


def test_no_import_cycles():
    cycle = _cycle(_graph())
    assert cycle is None, " -> ".join(cycle)


def test_no_module_over_600_lines():
    long = {str(f.relative_to(PKG)): n for f in FILES if (n := f.read_text().count("\n")) > 600}
    assert not long, long


def _long_functions():
    out = {}
    for f in FILES:
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = node.end_lineno - node.lineno + 1
                if n > 80:
                    out[f"{_name(f)}.{node.name}"] = n
    return out


def test_at_most_three_functions_over_80_lines():
    assert len(LONG_FUNCTIONS_ALLOWED) <= 3
    long = _long_functions()
    assert set(long) <= set(LONG_FUNCTIONS_ALLOWED), {k: v for k, v in long.items() if k not in LONG_FUNCTIONS_ALLOWED}


def test_no_private_names_imported_across_modules():
    found = []
    for f in FILES:
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, ast.ImportFrom) and (node.level or (node.module or "").startswith("irdic")):
                found += [f"{f.relative_to(PKG)}:{node.lineno}: {a.name}" for a in node.names
                          if a.name.startswith("_") and not a.name.startswith("__")]
    assert not found, found


@pytest.mark.parametrize("stage", ["couple", "fields", "figures", "export"])
def test_stage_modules_import_no_other_stage_entry(stage):
    # a stage's code hash must not change with another stage's entry module
    deps = _graph()[f"irdic.stages.{stage}"]
    from irdic.codehash import STAGES

    assert not {d for d in deps if d.startswith("irdic.stages.") and d.rsplit(".", 1)[1] in STAGES}
