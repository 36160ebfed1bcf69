"""The package's shape: no import cycles, short modules and functions, no private imports, thin stage entries.

The stages (``irdic/stages/``) only read their stores, call the domain
packages and write their store; the domain never imports a stage, so a change
to a model is not a change to a stage and each stage's code hash
(:mod:`irdic.codehash`) covers what it runs.
"""

import ast
import re
from pathlib import Path

import pytest

from irdic.codehash import module_imports

ROOT = Path(__file__).resolve().parents[1]
PKG = ROOT / "irdic"
FILES = sorted(PKG.rglob("*.py"))

#: functions allowed over 80 lines, with the reason (at most three in the package)
LONG_FUNCTIONS_ALLOWED: dict[str, str] = {}

#: the modules that may import irdic.stages: the stages themselves and the two ways of running them
#: (the Snakemake scripts under scripts/ and workflow/ are outside the package and checked apart)
STAGE_IMPORTERS = ("irdic.stages", "irdic.cli", "irdic.pipeline")

#: a stage entry reads its stores, calls the domain and writes its store: about this many lines at most
STAGE_MODULE_LINES = 150

#: stage modules allowed over STAGE_MODULE_LINES, with the reason (none today)
LONG_STAGE_MODULES_ALLOWED: dict[str, str] = {}


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


def _imports_stages(deps) -> list[str]:
    return sorted(d for d in deps if d == "irdic.stages" or d.startswith("irdic.stages."))


def test_only_the_stages_cli_and_pipeline_import_the_stages():
    # the domain never reaches up to a stage entry or a stage helper (irdic.stages.common)
    found = {m: _imports_stages(deps) for m, deps in _graph().items()
             if not any(m == s or m.startswith(s + ".") for s in STAGE_IMPORTERS) and _imports_stages(deps)}
    assert not found, found


def test_the_rule_above_catches_a_domain_module_importing_a_stage(tmp_path):
    pkg = tmp_path / "irdic"
    (pkg / "stages").mkdir(parents=True)
    for f in ("__init__.py", "stages/__init__.py", "stages/common.py"):
        (pkg / f).write_text("")
    (pkg / "model.py").write_text("def f():\n    from .stages.common import paths\n")
    assert _imports_stages(module_imports(pkg / "model.py", pkg)) == ["irdic.stages", "irdic.stages.common"]


def test_stage_package_holds_only_stage_entries():
    from irdic.codehash import STAGES

    extra = {f.stem for f in (PKG / "stages").glob("*.py")} - set(STAGES) - {"__init__", "common"}
    assert not extra, f"domain code belongs in a domain package, not in irdic/stages/: {sorted(extra)}"


def test_stage_entries_are_short():
    long = {f.name: n for f in (PKG / "stages").glob("*.py")
            if (n := f.read_text().count("\n")) > STAGE_MODULE_LINES and f.name not in LONG_STAGE_MODULES_ALLOWED}
    assert not long, long


def test_workflow_scripts_call_one_stage_entry():
    # a Snakemake script reads snakemake.input/params/threads and calls irdic.stages.<stage>: nothing else of irdic
    for f in sorted((ROOT / "scripts").glob("*.py")):
        names = re.findall(r"^\s*(?:from|import) (irdic[\w.]*)", f.read_text(), flags=re.M)
        assert names and set(names) == {"irdic.stages"}, (f.name, names)


#: words that say where code came from rather than what it does (an issue number, a work session, a part of a plan)
PROCESS_WORDS = re.compile(r"\bissues? #?\d+|\bsessions?\b|\bpart \d+\b", re.IGNORECASE)


def test_no_process_words_in_the_product():
    texts = [*FILES, ROOT / "README.md", ROOT / "benchmarks" / "README.md", *sorted((ROOT / "docs").glob("*.md")),
             *sorted((ROOT / "benchmarks").glob("*.py"))]
    found = [f"{f.relative_to(ROOT)}:{n}: {line.strip()[:80]}" for f in texts if f.is_file()
             for n, line in enumerate(f.read_text(encoding="utf-8").splitlines(), 1) if PROCESS_WORDS.search(line)]
    assert not found, found


def test_the_process_words_rule_sees_them():
    assert PROCESS_WORDS.search("(issue 15, part 4)") and PROCESS_WORDS.search("the ninth session's code")
    assert not PROCESS_WORDS.search("the round patch of the issued frames, in parts")


#: dotted names in the texts that are not references: examples of the notation, file names
NOT_REFERENCES = {"irdic.a", "irdic.a.b", "irdic.yaml"}


def _resolves(name: str) -> bool:
    import importlib

    parts = name.split(".")
    for k in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:k]))
        except ImportError:
            continue
        for attr in parts[k:]:
            if not hasattr(obj, attr):
                return False
            obj = getattr(obj, attr)
        return True
    return False


def test_dotted_references_name_what_exists():
    # after a module moves, a docstring or page that still names its old path points nowhere
    texts = [*FILES, ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")), ROOT / "benchmarks" / "README.md",
             *sorted((ROOT / "benchmarks").glob("*.py")), *sorted((ROOT / "workflow" / "rules").glob("*.smk"))]
    names = {m.group(0).rstrip(".") for f in texts if f.is_file()
             for m in re.finditer(r"\birdic(?:\.[A-Za-z_]\w*)+", f.read_text(encoding="utf-8"))}
    bad = sorted(n for n in names - NOT_REFERENCES if not _resolves(n))
    assert not bad, bad
    assert not _resolves("irdic.stages.uncertainty") and _resolves("irdic.uncertainty.model.uncertainties")
