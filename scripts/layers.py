#!/usr/bin/env python3
"""Checks that no module imports from a layer above its own.

The layers are written once, in docs/ARCHITECTURE.md's "Layers" section: a fenced block
per crate whose first line is `layers CRATE_SRC_DIR` and whose lines name the top-level
modules of each layer, the lowest first:

    layers driver/src
    1 hash atomic
    2 scene
    ...

A module may import from its own layer and those below it. Every `crate::…` path in code
(in `use` items, braces included, and inline paths such as `crate::x::f()`) and every
`super::…` path that climbs out of its top-level module is an import of the top-level module
it names. Lines starting with `//` and test code (`#[cfg(test)] mod …` blocks and files of a
module named `tests`) are left out: a test may reach above the code it tests.

Usage: scripts/layers.py [CRATE_SRC_DIR...]  (default: every crate the doc lists)
Exit 1, naming file:line and the two layers, when a module imports from a layer above it
or a top-level module has no layer."""
import os, re, sys

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
DOC = os.path.join(ROOT, 'docs', 'ARCHITECTURE.md')


def read_layers():
    """{crate src dir: {top-level module: (layer number, line of the doc)}} from the doc."""
    crates, current, in_block = {}, None, False
    for line in open(DOC, encoding="utf-8"):
        s = line.strip()
        if s.startswith("```"):
            in_block, current = not in_block, None
            continue
        if in_block is not True:
            continue
        if current is None:
            m = re.fullmatch(r"layers\s+(\S+)", s)
            if m:
                current = m.group(1)
                crates[current] = {}
            else:
                in_block = "other"  # another kind of fenced block: read past it
            continue
        m = re.fullmatch(r"(\d+)\s+(.+)", s)
        if m:
            for name in m.group(2).split():
                crates[current][name] = int(m.group(1))
    return crates


def test_blocks(lines):
    """Indices of lines inside `#[cfg(test)] mod NAME { … }` blocks."""
    skip, i = set(), 0
    while i < len(lines):
        if lines[i].strip().startswith("#[cfg(test)]"):
            j = i + 1
            while j < len(lines) and lines[j].strip().startswith("#["):
                j += 1
            if j < len(lines) and re.match(r"\s*(pub(\([^)]*\))?\s+)?mod\s+\w+\s*\{", lines[j]):
                depth, k = 0, j
                while k < len(lines):
                    depth += lines[k].count("{") - lines[k].count("}")
                    skip.add(k)
                    if depth <= 0:
                        break
                    k += 1
                skip.update(range(i, j))
                i = k + 1
                continue
        i += 1
    return skip


def crate_paths(text):
    """(offset, top-level module) of every `crate::…` path, braces expanded one level."""
    for m in re.finditer(r"\bcrate::(\{[^{}]*(?:\{[^{}]*\}[^{}]*)*\}|\w+)", text):
        target = m.group(1)
        if target.startswith("{"):
            inner, depth, item = target[1:-1], 0, ""
            items = []
            for ch in inner:
                if ch == "{":
                    depth += 1
                elif ch == "}":
                    depth -= 1
                if ch == "," and depth == 0:
                    items.append(item)
                    item = ""
                else:
                    item += ch
            items.append(item)
            for it in items:
                it = it.strip()
                if it:
                    yield m.start(), re.match(r"\w+", it).group(0)
        else:
            yield m.start(), target


def check(src, layers):
    bad = []
    src_abs = os.path.join(ROOT, src)
    for d, _, fs in sorted(os.walk(src_abs)):
        for f in sorted(fs):
            if not f.endswith(".rs"):
                continue
            path = os.path.join(d, f)
            mod = os.path.relpath(path, src_abs)[:-3].split(os.sep)
            if mod[-1] in ("mod", "lib", "main"):
                mod = mod[:-1]
            if "tests" in mod or not mod:
                continue
            top = mod[0]
            if top not in layers:
                bad.append(f'{os.path.relpath(path, ROOT)}:1: module `{top}` has no layer in docs/ARCHITECTURE.md')
                continue
            lines = open(path, encoding="utf-8").read().split("\n")
            skip = test_blocks(lines)
            for n, line in enumerate(lines):
                if n in skip or line.strip().startswith("//"):
                    continue
                code = line.split("//")[0]
                targets = [t for _, t in crate_paths(code)]
                for sm in re.finditer(r"\b((?:super::)+)(\w+)", code):
                    ups = sm.group(1).count("super::")
                    # From a file's own module: as many `super`s as its depth leave its
                    # top-level module (inline `mod` blocks, rarer, are not counted).
                    if ups >= len(mod):
                        targets.append(sm.group(2))
                for t in targets:
                    if t in ("self", "super") or t == top:
                        continue
                    if t not in layers:
                        continue  # an item of the crate root (a macro, a re-export)
                    if layers[t] > layers[top]:
                        bad.append(
                            f"{os.path.relpath(path, ROOT)}:{n + 1}: `{top}` (layer {layers[top]}) "
                            f"imports `{t}` (layer {layers[t]}), a layer above it")
    return bad


def main():
    crates = read_layers()
    wanted = sys.argv[1:] or sorted(crates)
    failed = False
    for src in wanted:
        src = os.path.normpath(src)
        if src not in crates:
            print(f'layers.py: docs/ARCHITECTURE.md has no `layers {src}` block', file=sys.stderr)
            failed = True
            continue
        bad = check(src, crates[src])
        for b in bad:
            print(b)
        print(f"{src}: {len(set(crates[src].values()))} layers, {len(bad)} upward import(s)")
        failed |= bool(bad)
    sys.exit(1 if failed else 0)


main()
