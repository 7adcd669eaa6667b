#!/usr/bin/env python3
"""Lists the imports between the crate's modules and fails on a cycle.

Each file under src/ is a module (`src/preprocess/model.rs` is `preprocess::model`, a `mod.rs`
is its folder's module). An edge A -> B is a path `crate::B...` (or `super::...` resolved) in
A's code outside comments and unit tests, B the longest module the path names. Edges between a module and its
own ancestors or descendants are left out: a parent declares its children and re-exports their
items, and a child may use what its parent defines; a cycle is a circle between modules that
neither contains. The same check runs again on the folders under src/ (each top-level module with
everything below it): `scene` -> `preprocess` and `preprocess` -> `scene` through any of their
files is a circle between floors even where no two files form one. Prints the edges with
--list; prints every strongly connected set of two or more modules or folders and exits 1
where there is one.

    python3 tools/module_cycles.py [--list] [SRC]
"""

import re
import sys
from pathlib import Path


def module_of(path, src):
    parts = list(path.relative_to(src).with_suffix("").parts)
    if parts[-1] in ("mod", "lib", "main"):
        parts = parts[:-1]
    return tuple(parts)


def strip_comments(text):
    """The code of `text` without comments and without its unit tests (`#[cfg(test)] mod
    tests`, at the end of a file by the crate's convention): a test may use any module."""
    text = re.split(r"#\[cfg\(test\)\]\s*mod\s+\w+", text)[0]
    text = re.sub(r"/\*.*?\*/", "", text, flags=re.S)
    return "\n".join(re.sub(r"//.*", "", line) for line in text.splitlines())


def references(text, here, modules):
    """The modules that `crate::` and `super::` paths in `text` name, seen from `here`."""
    found = set()
    for m in re.finditer(r"\b((?:crate|super)(?:::\w+)+)", text):
        words = m.group(1).split("::")
        if words[0] == "crate":
            path = words[1:]
        else:
            base = list(here)
            while words and words[0] == "super":
                base = base[:-1]
                words = words[1:]
            path = base + words
        for n in range(len(path), 0, -1):
            if tuple(path[:n]) in modules:
                found.add(tuple(path[:n]))
                break
    # `use crate::{a, b::c}` groups.
    for m in re.finditer(r"use\s+crate::\{([^}]*)\}", text, flags=re.S):
        for item in m.group(1).split(","):
            path = [w for w in item.strip().split("::") if w and w != "self"]
            for n in range(len(path), 0, -1):
                if tuple(path[:n]) in modules:
                    found.add(tuple(path[:n]))
                    break
    return found


def related(a, b):
    return a[: len(b)] == b or b[: len(a)] == a


def strongly_connected(nodes, edges):
    index, low, stack, on, out = {}, {}, [], set(), []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(edges.get(v, ())):
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
            out.append(sorted(group))

    sys.setrecursionlimit(10000)
    for v in sorted(nodes):
        if v not in index:
            visit(v)
    return out


def main(argv):
    listing = "--list" in argv
    args = [a for a in argv if not a.startswith("--")]
    src = Path(args[0]) if args else Path(__file__).resolve().parent.parent / "src"
    files = sorted(src.rglob("*.rs"))
    modules = {module_of(f, src) for f in files}
    edges = {}
    for f in files:
        here = module_of(f, src)
        for target in references(strip_comments(f.read_text()), here, modules):
            if not related(here, target):
                edges.setdefault(here, set()).add(target)
    name = lambda m: "::".join(m) or "crate"
    if listing:
        for a in sorted(edges):
            print(f"{name(a)} -> {', '.join(name(b) for b in sorted(edges[a]))}")
    cycles = [g for g in strongly_connected(modules, edges) if len(g) > 1]
    for g in cycles:
        print("cycle: " + " <-> ".join(name(m) for m in g))
    # Folders: the top-level modules, each standing for everything below it.
    folders = {m[:1] for m in modules if m}
    folder_edges, through = {}, {}
    for a, targets in edges.items():
        for b in targets:
            if a[:1] and b[:1] and a[:1] != b[:1]:
                folder_edges.setdefault(a[:1], set()).add(b[:1])
                through.setdefault((a[:1], b[:1]), []).append(f"{name(a)} -> {name(b)}")
    folder_cycles = [g for g in strongly_connected(folders, folder_edges) if len(g) > 1]
    for g in folder_cycles:
        print("folder cycle: " + " <-> ".join(name(m) for m in g))
        members = set(g)
        for a in g:
            for b in sorted(folder_edges.get(a, ())):
                if b in members:
                    print(f"  {name(a)} -> {name(b)}: {', '.join(sorted(through[(a, b)]))}")
    print(
        f"{len(modules)} modules, {sum(len(v) for v in edges.values())} imports, {len(cycles)} cycles; "
        f"{len(folders)} folders, {sum(len(v) for v in folder_edges.values())} imports, {len(folder_cycles)} cycles"
    )
    return 1 if cycles or folder_cycles else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
