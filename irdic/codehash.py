"""A short hash of irdic's own source code, per stage.

Snakemake re-runs a job when its ``params`` change, but it does not look
inside an installed Python package. Each rule passes the hash of the irdic
modules its stage uses as a parameter, so editing or upgrading that code
re-runs exactly the stages it affects.

The modules of a stage are those its entry module ``irdic.stages.<stage>``
imports, transitively: a static walk of the import statements (those inside
functions included, since irdic imports heavy modules lazily), restricted
to irdic's own modules. Importing ``irdic.a.b`` runs ``irdic/a/__init__.py``
too, so package initialisers count as imported. Nothing is imported while
hashing.
"""

from __future__ import annotations

import ast
import hashlib
from functools import lru_cache
from pathlib import Path

__all__ = ["code_hash", "stage_modules", "module_imports", "STAGES"]

_ROOT = Path(__file__).resolve().parent

#: the stages, each with its entry module irdic.stages.<stage>
STAGES = ("demo", "ingest_ir", "ingest_dic", "ingest_machine", "calibrate", "couple", "fields", "heat", "figures",
          "export", "report")


def _module_file(name: str, root: Path) -> Path | None:
    """The source file of irdic module ``name`` (dotted, starting with ``irdic``) under ``root``, if any."""
    parts = name.split(".")[1:]
    base = root.joinpath(*parts) if parts else root
    for f in (base.with_suffix(".py") if parts else None, base / "__init__.py"):
        if f is not None and f.is_file():
            return f
    return None


def _module_name(f: Path, root: Path) -> str:
    rel = f.relative_to(root).with_suffix("")
    parts = [p for p in rel.parts if p != "__init__"]
    return ".".join(["irdic", *parts])


def _with_parents(name: str) -> list[str]:
    """``irdic.a.b`` -> ``irdic``, ``irdic.a``, ``irdic.a.b`` (importing a module runs its packages)."""
    parts = name.split(".")
    return [".".join(parts[:k]) for k in range(1, len(parts) + 1)]


def module_imports(f: Path, root: Path | None = None) -> set[str]:
    """The irdic modules that file ``f`` imports anywhere in it (dotted names, parents included).

    Relative imports are resolved against the file's package; ``from X
    import y`` counts ``X.y`` when that is a module, else ``X``.
    """
    root = _ROOT if root is None else root
    me = _module_name(f, root)
    package = me if f.name == "__init__.py" else me.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(ast.parse(f.read_text(encoding="utf-8"), filename=str(f))):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[:len(base) - (node.level - 1)]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            targets = [mod] + [f"{mod}.{a.name}" for a in node.names]
        else:
            continue
        for t in targets:
            if (t == "irdic" or t.startswith("irdic.")) and _module_file(t, root) is not None:
                found.update(_with_parents(t))
    return found


def stage_modules(stage: str, root: Path | None = None) -> tuple[str, ...]:
    """Files (relative to the package, sorted) of every irdic module the stage imports, transitively.

    Raises
    ------
    KeyError
        ``stage`` is not one of :data:`STAGES`.
    """
    if stage not in STAGES:
        raise KeyError(f"unknown stage {stage!r}; expected one of {', '.join(STAGES)}")
    root = _ROOT if root is None else root
    todo = _with_parents(f"irdic.stages.{stage}")
    seen: set[str] = set()
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        seen.add(name)
        f = _module_file(name, root)
        if f is not None:
            todo.extend(module_imports(f, root) - seen)
    files = (_module_file(n, root) for n in seen)
    return tuple(sorted(str(f.relative_to(root)) for f in files if f is not None))


@lru_cache(maxsize=None)
def code_hash(*parts: str) -> str:
    """SHA-256 (first 12 hex digits) of the given irdic modules' source files.

    Parameters
    ----------
    *parts : str
        Stage names of :data:`STAGES` (their modules, :func:`stage_modules`),
        or module files (``"store.py"``) and sub-package folders (``"io"``)
        relative to the irdic package. Missing files are skipped.
    """
    names: list[str] = []
    for p in parts:
        names.extend(stage_modules(p, _ROOT) if p in STAGES else (p,))
    h = hashlib.sha256()
    for name in sorted(set(names)):
        target = _ROOT / name
        files = sorted(target.rglob("*.py")) if target.is_dir() else [target]
        for f in files:
            if f.is_file():
                h.update(str(f.relative_to(_ROOT)).encode())
                h.update(f.read_bytes())
    return h.hexdigest()[:12]
