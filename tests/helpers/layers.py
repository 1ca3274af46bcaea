"""The package's import contract, checked from the source (no import is executed).

The stages of :data:`LAYERS`, bottom first: a module may import its own stage and the stages
below it, never one above; stages that share a row are siblings and may not import each
other.  No module may take part in an import circle (imports inside functions count: a circle
is a circle for whoever reads the code).  OpenGL, glfw and imgui are imported only in the
stages of :data:`GL_STAGES`.
"""

from __future__ import annotations

import ast
from dataclasses import dataclass
from pathlib import Path

#: bottom → top; a tuple holds sibling stages
LAYERS = (
    ("base",),
    ("config",),
    ("outline", "sim"),
    ("veins",),
    ("blade",),
    ("pipeline",),
    ("appearance",),
    ("export",),
    ("render",),
    ("interactive",),
    ("scene", "compare"),
    ("gui",),
    ("measure",),
    ("commands",),
    ("cli",),
    ("__main__",),
)
GL_MODULES = ("moderngl", "glfw", "imgui_bundle", "OpenGL")
GL_STAGES = ("render", "gui")


@dataclass(frozen=True)
class Edge:
    source: str      # module that imports
    target: str      # module imported
    line: int


def stage_of(module: str) -> str:
    """``leafsim.sim.run`` → ``sim``; the package root → ``""`` (below everything)."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def rank(stage: str) -> int:
    if stage == "":
        return -1
    for i, row in enumerate(LAYERS):
        if stage in row:
            return i
    raise KeyError(stage)


def module_name(root: Path, path: Path) -> str:
    rel = path.relative_to(root.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def modules(root: Path) -> dict[str, Path]:
    """Every module of the package at ``root`` (the ``leafsim`` folder)."""
    return {module_name(root, p): p for p in sorted(root.rglob("*.py"))}


def edges(root: Path) -> tuple[list[Edge], list[Edge]]:
    """(imports between the package's modules, imports of GL/imgui packages)."""
    mods = modules(root)
    pkg = root.name
    inner, gl = [], []
    for name, path in mods.items():
        is_pkg = path.name == "__init__.py"
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for n in ast.walk(tree):
            targets = []
            if isinstance(n, ast.Import):
                targets = [a.name for a in n.names]
            elif isinstance(n, ast.ImportFrom):
                if n.level:
                    base = name.split(".") if is_pkg else name.split(".")[:-1]
                    base = base[: len(base) - (n.level - 1)]
                    mod = ".".join(base + ([n.module] if n.module else []))
                else:
                    mod = n.module or ""
                targets = [f"{mod}.{a.name}" if f"{mod}.{a.name}" in mods else mod for a in n.names]
            for t in targets:
                if t.split(".")[0] in GL_MODULES:
                    gl.append(Edge(name, t, n.lineno))
                elif t.split(".")[0] == pkg:
                    while t not in mods and "." in t:
                        t = t.rsplit(".", 1)[0]
                    if t != name:
                        inner.append(Edge(name, t, n.lineno))
    return inner, gl


def upward(root: Path) -> list[str]:
    """Imports that point up the stage order or sideways between sibling stages."""
    out = []
    for e in edges(root)[0]:
        s, t = stage_of(e.source), stage_of(e.target)
        if s == t:
            continue
        if rank(t) > rank(s) or (rank(t) == rank(s) and t != s):
            out.append(f"{e.source} (stage {s}) imports {e.target} (stage {t}) at line {e.line}")
    return out


def circles(root: Path) -> list[list[str]]:
    """Strongly connected groups of more than one module (Tarjan)."""
    graph: dict[str, set[str]] = {m: set() for m in modules(root)}
    for e in edges(root)[0]:
        graph[e.source].add(e.target)
    index, low, on, stack, out = {}, {}, set(), [], []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = []
            while True:
                w = stack.pop()
                on.discard(w)
                group.append(w)
                if w == v:
                    break
            if len(group) > 1:
                out.append(sorted(group))

    for v in graph:
        if v not in index:
            visit(v)
    return out


def gl_outside(root: Path) -> list[str]:
    """GL/imgui imports outside :data:`GL_STAGES`."""
    return [f"{e.source} imports {e.target} at line {e.line}" for e in edges(root)[1] if stage_of(e.source) not in GL_STAGES]


def unknown_stages(root: Path) -> list[str]:
    """Top-level modules and folders that no row of :data:`LAYERS` names."""
    bad = set()
    for m in modules(root):
        s = stage_of(m)
        try:
            rank(s)
        except KeyError:
            bad.add(s)
    return sorted(bad)
