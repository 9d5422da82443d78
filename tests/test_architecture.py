"""The house rules of docs/architecture.md, checked on the source: every module of src/robotadapt sits in a layer of the
page's table, imports only from its own layer or below, never in a circle, and never a private name of another module."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SRC = ROOT / "src" / "robotadapt"
PAGE = ROOT / "docs" / "architecture.md"


def layers(text: str) -> dict[str, int]:
    """Top-level package or module name → layer number, from the page's table."""
    out = {}
    for number, cell in re.findall(r"^\| (\d+) \| ([^|]+) \|", text, flags=re.M):
        for name in re.findall(r"`([\w]+)`", cell):
            out[name] = int(number)
    return out


def module_name(path: Path, src: Path = SRC) -> str:
    parts = list(path.relative_to(src.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports(path: Path, src: Path = SRC) -> list[tuple[str, list[str]]]:
    """(imported module, names) for every robotadapt import in the file, relative ones resolved."""
    name = module_name(path, src)
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    out = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if target.split(".")[0] == "robotadapt":
                out.append((target, [a.name for a in node.names]))
        elif isinstance(node, ast.Import):
            out += [(a.name, []) for a in node.names if a.name.split(".")[0] == "robotadapt"]
    return out


def graph(src: Path = SRC) -> dict[str, set[str]]:
    """Module → the robotadapt modules it imports (`from pkg import submodule` counts as importing the submodule)."""
    modules = {module_name(p, src): p for p in src.rglob("*.py")}
    edges: dict[str, set[str]] = {}
    for name, path in modules.items():
        deps = set()
        for target, names in imports(path, src):
            subs = {f"{target}.{n}" for n in names if f"{target}.{n}" in modules}
            deps |= subs or {target}
            if names and len(subs) < len(names):
                deps.add(target)
        edges[name] = deps - {name}
    return edges


def unit(module: str) -> str:
    """The layer unit of a module: its first component below robotadapt ('' for the package itself)."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """Every strongly connected component of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in edges.get(v, ()):
            if w not in edges:
                continue
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return out


def violations(src: Path, table: dict[str, int]) -> list[str]:
    """What breaks the rules, one line each."""
    edges = graph(src)
    out = []
    for module in sorted(edges):
        if unit(module) and unit(module) not in table:
            out.append(f"{module}: in no layer of docs/architecture.md")
    for module, deps in sorted(edges.items()):
        here = table.get(unit(module), 0) if unit(module) else 0
        for dep in sorted(deps):
            there = table.get(unit(dep), 0) if unit(dep) else 0
            if there > here:
                out.append(f"{module} (layer {here}) imports {dep} (layer {there}): upward")
    for component in cycles(edges):
        out.append("import circle: " + " -> ".join(component))
    for path in sorted(src.rglob("*.py")):
        for target, names in imports(path, src):
            private = [n for n in names if n.startswith("_") and not n.startswith("__")]
            if private and target != module_name(path, src):
                out.append(f"{module_name(path, src)} imports private {', '.join(private)} from {target}")
    return out


def test_the_package_keeps_the_house_rules():
    assert violations(SRC, layers(PAGE.read_text(encoding="utf-8"))) == []


def test_the_page_names_only_what_exists():
    on_disk = {p.stem if p.suffix == ".py" else p.name for p in SRC.iterdir()
               if (p.suffix == ".py" and p.stem != "__init__") or (p.is_dir() and (p / "__init__.py").exists())}
    assert set(layers(PAGE.read_text(encoding="utf-8"))) == on_disk


@pytest.mark.parametrize("files, expected", [
    ({"a/__init__.py": "", "a/x.py": "from ..b import y\n", "b/__init__.py": "", "b/y.py": "from ..a import x\n"},
     "import circle"),
    ({"a/__init__.py": "", "a/x.py": "def f():\n    from ..b.y import g\n", "b/__init__.py": "", "b/y.py": ""},
     "upward"),
    ({"a/__init__.py": "", "a/x.py": "", "b/__init__.py": "", "b/y.py": "from ..a.x import _hidden\n"}, "private"),
    ({"c/__init__.py": ""}, "in no layer"),
])
def test_a_planted_violation_is_caught(tmp_path, files, expected):
    """The checker itself: a circle, an upward import inside a function, a private name, a module in no layer."""
    src = tmp_path / "robotadapt"
    for name, text in files.items():
        (src / name).parent.mkdir(parents=True, exist_ok=True)
        (src / name).write_text(text)
    (src / "__init__.py").write_text("")
    found = violations(src, {"a": 1, "b": 2})
    assert any(expected in line for line in found), found
