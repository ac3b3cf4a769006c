#!/usr/bin/env python3
"""Checks the module structure of the Rust crates: no import cycles at any folder level, and
the layer order of docs/design.md (a lower layer never names a higher one).

A module's references are read from its code (comments and doc links are skipped): `crate::a::b`
paths, `use crate::{a, b::c}` groups, and `super::` / `self::` paths resolved against the
module. Inside every folder (a crate's `src/` included), the children (files and sub-folders)
form a graph with an edge a -> b when something in a names something in b; every strongly
connected component of more than one child is a cycle. Test modules (`#[cfg(test)] mod ... {`
to the end of a file, `tests.rs` and `test_support.rs` files) are skipped, as tests may reach across layers.

Usage: python3 scripts/check-layers.py [REPO]   (exit code 1 on any finding)
"""
import os
import re
import sys
from collections import defaultdict

# Layers of each crate's top-level modules, lowest first (docs/design.md, "Layers").
LAYERS = {
    "fuzzyq-core": [
        {"limits"},
        {"real", "error", "options"},
        {"partition", "action"},
        {"model"},
        {"q", "additive", "backup"},
        {"solver"},
        {"view"},
    ],
    "fuzzyq-sim": [
        {"error", "paper", "fs"},
        {"toml_doc"},
        {"model"},
        {"world"},
        {"learn"},
        {"io"},
        {"run", "memory", "slabs"},
        {"train"},
        {"compare"},
    ],
    "fuzzyq-gpu": [
        {"error", "reference", "memory", "batches", "unrolled"},
        {"context"},
        {"buffers"},
        {"parts"},
        {"kernels"},
        {"probe"},
        {"gpu"},
        {"last"},
        {"shape"},
        {"compile"},
        {"sweeps"},
    ],
    "fuzzyq-cli": [
        {"output"},
        {"plot"},
        {"cmd"},
    ],
}


def module_path(src, path):
    rel = os.path.relpath(path, src)[:-3].split(os.sep)
    if rel[-1] in ("mod", "lib", "main"):
        rel = rel[:-1]
    return tuple(rel)


def strip_tests(text):
    """The code of a file: without its test module and without comments (doc links are
    references for readers, not dependencies)."""
    m = re.search(r"#\[cfg\(test\)\]\s*mod\s+\w+\s*\{", text)
    text = text[: m.start()] if m else text
    return re.sub(r"//[^\n]*", "", text)


def expand_group(prefix, body):
    """`a::{b, c::{d, e}}` -> [a::b, a::c::d, a::c::e] (roughly)."""
    out, depth, cur = [], 0, ""
    for ch in body + ",":
        if ch == "{":
            depth += 1
        elif ch == "}":
            depth -= 1
        if ch == "," and depth == 0:
            item = cur.strip()
            cur = ""
            if not item:
                continue
            g = re.match(r"^([\w:]*?)::\{(.*)\}$", item, re.S)
            if g:
                out += expand_group(prefix + g.group(1).split("::"), g.group(2))
            else:
                out.append(prefix + item.split(" as ")[0].strip().split("::"))
            continue
        cur += ch
    return out


def references(text, here):
    """Absolute module paths (tuples) that `text`, in module `here`, names."""
    refs = []
    for m in re.finditer(r"\b(crate|super|self)((?:::\w+)+)(::\{[^;]*?\})?", text):
        head, tail, group = m.group(1), m.group(2), m.group(3)
        parts = [p for p in tail.split("::") if p]
        if head == "crate":
            base = []
        elif head == "self":
            base = list(here)
        else:
            base = list(here[:-1])
            while parts and parts[0] == "super":
                base = base[:-1]
                parts = parts[1:]
        if group:
            for p in expand_group(base + parts, group[3:-1]):
                refs.append(tuple(p))
        refs.append(tuple(base + parts))
    return refs


def reexports(files, modules):
    """`pub use` items: (module, name) path -> the path it re-exports, so that `crate::Item`
    counts as naming the module that defines `Item`."""
    out = {}
    for here, text in files.items():
        for m in re.finditer(r"\bpub(?:\([\w:]+\))?\s+use\s+([^;]+);", text):
            tree = m.group(1).strip()
            g = re.match(r"^([\w:]*?)::\{(.*)\}$", tree, re.S)
            paths = expand_group(g.group(1).split("::"), g.group(2)) if g else [tree.split("::")]
            for path in paths:
                name = path[-1]
                head, rest = path[0], path[1:]
                if head == "crate":
                    base = []
                elif head == "self":
                    base = list(here)
                elif head == "super":
                    base = list(here[:-1])
                elif tuple(here) + (head,) in modules:
                    base, rest = list(here) + [head], path[1:]
                else:
                    continue  # another crate's item
                out[tuple(here) + (name.split(" as ")[-1].strip(),)] = tuple(base + [p.split(" as ")[0].strip() for p in rest])
    return out


def resolve(ref, modules, exports):
    """The module `ref` names: its longest module prefix, after following re-exports."""
    for _ in range(8):
        k = len(ref)
        while k > 0 and ref[:k] not in modules:
            k -= 1
        if k < len(ref) and ref[: k + 1] in exports:
            ref = exports[ref[: k + 1]] + ref[k + 1 :]
            continue
        return ref[:k] if k > 0 else None
    return None


def check_crate(crate_dir, name):
    src = os.path.join(crate_dir, "src")
    files = {}
    for root, _, fs in os.walk(src):
        for f in fs:
            if f.endswith(".rs") and f not in ("tests.rs", "test_support.rs"):
                p = os.path.join(root, f)
                files[module_path(src, p)] = strip_tests(open(p).read())
    modules = set(files)
    # every folder: (folder path) -> children
    children = defaultdict(set)
    for m in modules:
        for i in range(len(m)):
            children[m[:i]].add(m[i])
    exports = reexports(files, modules)
    findings = []
    edges = defaultdict(lambda: defaultdict(set))  # folder -> a -> {b}
    for here, text in files.items():
        for ref in references(text, here):
            target = resolve(ref, modules, exports)
            if target is None:
                continue
            # common folder of here and target, and the children they sit under
            k = 0
            while k < min(len(here), len(target)) and here[k] == target[k]:
                k += 1
            if k == len(here) or k == len(target):
                continue  # a module naming itself, an ancestor or a descendant
            edges[here[:k]][here[k]].add(target[k])
    for folder, graph in sorted(edges.items()):
        for comp in scc(graph):
            if len(comp) > 1:
                where = "::".join(folder) or "src"
                findings.append(f"{name}: cycle in {where}/ among {sorted(comp)}")
    layers = LAYERS.get(name)
    if layers:
        rank = {m: i for i, layer in enumerate(layers) for m in layer}
        for top in sorted(children[()]):
            if top not in rank:
                findings.append(f"{name}: top-level module {top!r} has no declared layer")
        for a, targets in sorted(edges[()].items()):
            for b in sorted(targets):
                if a in rank and b in rank and rank[b] >= rank[a]:
                    findings.append(
                        f"{name}: {a} (layer {rank[a]}) names {b} (layer {rank[b]}): "
                        "a module may only name lower layers"
                    )
    return findings


def scc(graph):
    index, low, stack, on, out, counter = {}, {}, [], set(), [], [0]
    nodes = set(graph) | {b for bs in graph.values() for b in bs}

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            out.append(comp)

    for v in sorted(nodes):
        if v not in index:
            visit(v)
    return out


def main(repo):
    findings = []
    crates = os.path.join(repo, "crates")
    for name in sorted(os.listdir(crates)):
        if os.path.isdir(os.path.join(crates, name, "src")):
            findings += check_crate(os.path.join(crates, name), name)
    for f in findings:
        print(f)
    print(f"{len(findings)} finding(s)")
    return 1 if findings else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1] if len(sys.argv) > 1 else "."))
