"""froude's layers read from the source: every module's imports of froude (at the top of the file, inside
functions, and under ``if TYPE_CHECKING:``), the layer of each module, the imports that point up a layer and
the import circles. One parse for the test that keeps the layers (tests/test_layers.py) and the picture of
them (docs/make_architecture.py).

    python scripts/layers.py            # the layer graph, then every violation as file:line
"""
from __future__ import annotations

import ast
import sys
import textwrap
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PKG = REPO / "src" / "froude"

#: Bottom to top: a layer may import the layers below it, never one above. (layer, what it holds)
LAYERS = [
    ("core", "quaternions, skeleton, motion, FK and Jacobians; constants; the errors"),
    ("io", "BVH, glTF, per-frame tables, atomic writes, JSON; the bundled sample"),
    ("body", "body model (de Leva), joint roles, gait and contacts, characters, conventions, the take"),
    ("machine", "§4-5: units, dynamics, orbits, forces, fit, speed (§5.2), transition table and planner (§5.3)"),
    ("synthesis", "§6 input: reference cycle, time warp, IK targets"),
    ("ik", "§6: IK tasks, the batched whole-body solver and its kernels, the correction policy"),
    ("report", "the physics report (metrics, walk and path sections) and plots/renders (viz)"),
    ("flow", "orchestration: prepare / scale / accelerate / naive, results, speed range and goals"),
    ("api", "the public verbs (api, the package's lazy names)"),
    ("apps", "command line, studio, batch, demo, Blender add-on, signals"),
]
ORDER = {name: i for i, (name, _) in enumerate(LAYERS)}

#: The layer of a module by its name under froude (longest prefix wins); the packages are their own layer.
PLACES = {
    "froude": "api", "froude.__main__": "apps", "froude.api": "api", "froude.errors": "core",
    "froude.core": "core", "froude.io": "io", "froude.body": "body", "froude.machine": "machine",
    "froude.synthesis": "synthesis", "froude.ik": "ik", "froude.report": "report", "froude.viz": "report",
    "froude.flow": "flow", "froude.apps": "apps",
}

#: The mark an import inside a function carries to say why it is there: only to keep start-up fast.
LAZY_MARK = "# lazy:"


@dataclass(frozen=True)
class Import:
    """One import of a froude module: who, what, where, and how (top of file, in a function, types only)."""

    source: str       # importing module, e.g. "froude.io.bvh"
    target: str       # imported module, e.g. "froude.body.conventions"
    path: Path
    line: int
    in_function: bool
    types_only: bool  # under ``if TYPE_CHECKING:``: never runs
    marked: bool      # the statement (or the line above it) carries LAZY_MARK

    @property
    def where(self) -> str:
        path = self.path.relative_to(REPO) if self.path.is_relative_to(REPO) else self.path
        return f"{path.as_posix()}:{self.line}"


def layer_of(module: str) -> str:
    """'froude.machine.fit' -> 'machine': the layer of the longest PLACES prefix (KeyError if none)."""
    parts = module.split(".")
    for n in range(len(parts), 0, -1):
        place = PLACES.get(".".join(parts[:n]))
        if place is not None:
            return place
    raise KeyError(f"{module}: no layer (add it to scripts/layers.py PLACES)")


def modules(pkg: Path = PKG) -> dict[str, Path]:
    """{dotted module name: file} of every module under the package (a package is its __init__.py)."""
    out = {}
    for p in sorted(pkg.rglob("*.py")):
        rel = p.relative_to(pkg.parent).with_suffix("")
        out[".".join(rel.parts[:-1] if rel.name == "__init__" else rel.parts)] = p
    return out


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _statements(tree: ast.Module):
    """(import node, inside a function, under TYPE_CHECKING) for every import statement in the file."""
    def walk(node, in_function: bool, types_only: bool):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.Import, ast.ImportFrom)):
                yield child, in_function, types_only
            elif isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
                yield from walk(child, True, types_only)
            elif isinstance(child, ast.If) and _is_type_checking(child.test):
                for stmt in child.body:
                    yield from walk(ast.Module(body=[stmt], type_ignores=[]), in_function, True)
                for stmt in child.orelse:
                    yield from walk(ast.Module(body=[stmt], type_ignores=[]), in_function, types_only)
            else:
                yield from walk(child, in_function, types_only)
    yield from walk(tree, False, False)


def imports_of(name: str, path: Path, known: dict[str, Path]) -> list[Import]:
    """Every import of a froude module in one file; ``from X import y`` names X.y when that is a module."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    lines = path.read_text(encoding="utf-8").splitlines()
    found = []
    for node, in_function, types_only in _statements(ast.parse("\n".join(lines))):
        text = "\n".join(lines[max(node.lineno - 2, 0):node.end_lineno])
        marked = LAZY_MARK in text
        targets = []
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        else:
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            for a in node.names:
                targets.append(f"{mod}.{a.name}" if f"{mod}.{a.name}" in known else mod)
        for target in dict.fromkeys(targets):
            if target == "froude" or target.startswith("froude."):
                found.append(Import(name, target, path, node.lineno, in_function, types_only, marked))
    return found


def all_imports(pkg: Path = PKG) -> list[Import]:
    known = modules(pkg)
    return [imp for name, path in known.items() for imp in imports_of(name, path, known)]


def upward(imps: list[Import]) -> list[str]:
    """'file:line: a (layer) imports b (layer)' for every import that points up a layer."""
    return [f"{i.where}: {i.source} ({layer_of(i.source)}) imports {i.target} ({layer_of(i.target)})"
            for i in imps if ORDER[layer_of(i.target)] > ORDER[layer_of(i.source)]]


def unmarked_lazy(imps: list[Import]) -> list[str]:
    """'file:line: ...' for every import of froude inside a function without the LAZY_MARK comment."""
    return [f"{i.where}: {i.source} imports {i.target} inside a function without '{LAZY_MARK} <why>'"
            for i in imps if i.in_function and not i.types_only and not i.marked]


def circles(imps: list[Import]) -> list[str]:
    """Each import circle among modules (imports that run: TYPE_CHECKING ones never do), as its edges."""
    graph: dict[str, dict[str, Import]] = {}
    for i in imps:
        if not i.types_only and i.target != i.source:
            graph.setdefault(i.source, {}).setdefault(i.target, i)
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    groups: list[list[str]] = []

    def connect(v: str) -> None:  # Tarjan's strongly connected components
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph.get(v, {}):
            if w not in index:
                connect(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                group.append(w)
                if w == v:
                    break
            if len(group) > 1:
                groups.append(sorted(group))

    sys.setrecursionlimit(max(10_000, sys.getrecursionlimit()))
    for v in sorted(graph):
        if v not in index:
            connect(v)
    out = []
    for group in sorted(groups):
        members = set(group)
        edges = [f"{i.source} -> {i.target} ({i.where})" for v in group for t, i in sorted(graph[v].items())
                 if t in members]
        out.append("circle of " + ", ".join(group) + ": " + "; ".join(edges))
    return out


def layer_edges(imps: list[Import]) -> Counter:
    """Counter of (from layer, to layer) over the imports between different layers."""
    return Counter((layer_of(i.source), layer_of(i.target)) for i in imps
                   if layer_of(i.source) != layer_of(i.target))


def graph_text(imps: list[Import], mods: dict[str, Path]) -> str:
    """The layers top to bottom, each with its modules and the layers it imports (with counts)."""
    count = layer_edges(imps)
    by_layer: dict[str, list[str]] = {name: [] for name, _ in LAYERS}
    for name in mods:
        by_layer[layer_of(name)].append(name.removeprefix("froude.") if name != "froude" else "froude")
    rows = []
    for name, what in reversed(LAYERS):
        uses = ", ".join(f"{dst} {n}" for (src, dst), n in sorted(count.items(), key=lambda e: -ORDER[e[0][1]])
                         if src == name)
        listed = textwrap.fill(", ".join(sorted(by_layer[name])), 110, initial_indent=" " * 10 + "modules: ",
                               subsequent_indent=" " * 19)
        rows.append(f"{name:9s} {what}\n{listed}\n          imports: {uses or '-'}")
    return "\n".join(rows)


def main() -> int:
    mods = modules()
    imps = all_imports()
    print(graph_text(imps, mods))
    problems = upward(imps) + circles(imps) + unmarked_lazy(imps)
    for line in problems:
        print(line)
    n_lazy = sum(i.in_function for i in imps)
    print(f"{len(imps)} imports of froude ({n_lazy} inside functions); {len(upward(imps))} upward, "
          f"{len(circles(imps))} circle(s), {len(unmarked_lazy(imps))} unmarked import(s) inside functions")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
