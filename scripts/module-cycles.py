#!/usr/bin/env python3
"""Module import graph of a crate's src/ and its cycles (strongly connected components).

Every `crate::…`, `super::…` and `self::…` path in code (lines starting with `//` and
everything from the first `#[cfg(test)]` on are skipped) becomes an edge to the module
that defines the item; a name reached through a parent module's own `use` (a child's
`super::NAME` where the parent did `use sibling::NAME`) is followed to the sibling that
defines it. Edges between a module and its ancestors are the module tree, not imports.
Usage: scripts/module-cycles.py CRATE_SRC_DIR [MODULE...]  (MODULE: print its edges)
Exit 1 when there is a cycle (CI runs it on driver/src and kernels/src)."""
import os, re, sys
root = sys.argv[1]
mods = {}
for d, _, fs in os.walk(root):
    for f in fs:
        if f.endswith(".rs"):
            p = os.path.relpath(os.path.join(d, f), root)[:-3].split(os.sep)
            if p[-1] in ("mod", "lib", "main"): p = p[:-1]
            mods["::".join(p)] = os.path.join(d, f)
def code(path):
    out = []
    for line in open(path):
        s = line.strip()
        if s.startswith("#[cfg(test)]"): break
        if s.startswith("//"): continue
        out.append(line)
    return "".join(out)
texts = {m: code(p) for m, p in mods.items()}
def absolute(m, parts):
    me = m.split("::") if m else []
    if parts[0] == "crate": return parts[1:]
    if parts[0] == "self": return me + parts[1:]
    if parts[0] == "super":
        n = 0
        while n < len(parts) and parts[n] == "super": n += 1
        return me[:len(me) - n] + parts[n:]
    if "::".join(me + parts[:1]) in mods: return me + parts   # a child module
    return None
def expand(text):
    """`a::b::{c, d::e as f}` → ['a::b::c', 'a::b::d::e'] (one level of braces)."""
    items = []
    for g in re.finditer(r"\b((?:crate|super|self|\w+)(?:::\w+)*)::\{([^{}]*)\}", text):
        for it in g.group(2).split(","):
            it = it.strip().split(" as ")[0].strip()
            if it and it != "self": items.append(g.group(1) + "::" + it)
            elif it == "self": items.append(g.group(1))
    return items
imports = {m: {} for m in mods}   # module → name → absolute path of what it imports
for m, t in texts.items():
    for u in re.finditer(r"\buse\s+([^;]+);", t):
        spec = u.group(1).replace("\n", " ")
        paths = expand(spec) if "{" in spec else [spec.split(" as ")[0].strip()]
        for p in paths:
            a = absolute(m, [x for x in p.split("::") if x])
            if a: imports[m][a[-1]] = a
def resolve(parts, depth=0):
    for n in range(len(parts), -1, -1):
        m = "::".join(parts[:n])
        if m in mods:
            rest = parts[n:]
            if rest and rest[0] in imports[m] and depth < 8:
                target = imports[m][rest[0]]
                if target != parts[:n] + rest[:1]:
                    return resolve(target + rest[1:], depth + 1)
            return m
    return None
edges = {m: set() for m in mods}
for m, t in texts.items():
    refs = [r.group(0) for r in re.finditer(r"\b(?:crate|super|self)(?:::\w+)+", t)]
    refs += [p for p in expand(t) if p.split("::")[0] in ("crate", "super", "self")]
    for r in refs:
        a = absolute(m, r.split("::"))
        if a is None: continue
        target = resolve(a)
        if target is None or target == m: continue
        if m.startswith(target + "::") or target == "" or m == "" or target.startswith(m + "::"): continue
        edges[m].add(target)
idx, low, st, on, comps, c = {}, {}, [], set(), [], [0]
sys.setrecursionlimit(10000)
def sc(v):
    idx[v] = low[v] = c[0]; c[0] += 1; st.append(v); on.add(v)
    for w in sorted(edges[v]):
        if w not in idx: sc(w); low[v] = min(low[v], low[w])
        elif w in on: low[v] = min(low[v], idx[w])
    if low[v] == idx[v]:
        comp = []
        while True:
            w = st.pop(); on.discard(w); comp.append(w)
            if w == v: break
        if len(comp) > 1: comps.append(sorted(comp))
for v in sorted(mods):
    if v not in idx: sc(v)
for comp in comps:
    print("cycle:", " ⇄ ".join(comp))
    for a in comp: print("   ", a, "->", ", ".join(sorted(b for b in edges[a] if b in comp)))
print(f"{root}: {len(mods)} modules, {sum(map(len, edges.values()))} import edges, {len(comps)} cycle(s)")
if len(sys.argv) > 2:
    for m in sys.argv[2:]: print("   ", m, "->", ", ".join(sorted(edges[m])))
sys.exit(1 if comps else 0)
