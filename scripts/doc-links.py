#!/usr/bin/env python3
"""Check that every relative Markdown link to a `.md` file (with or without `#anchor`) in
README.md, CHANGELOG.md and docs/ resolves: the file exists and, with an anchor, the file has
a heading whose GitHub anchor is that one (lower-case; spaces to '-'; punctuation dropped but
'-' and '_'; a repeated heading gets -1, -2, ...). Also lists quoted doc sections named as
`X.md, "Title"` whose title is no heading (or bold lead) of X.md. Exit 1 on a broken link.

Usage: scripts/doc-links.py [ROOT]   (ROOT defaults to the repository root)
"""
import os
import re
import sys

ROOT = os.path.abspath(sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(__file__), ".."))


def anchor(title):
    t = title.strip().lower()
    t = re.sub(r"[^\w\- ]", "", t, flags=re.UNICODE)
    return t.replace(" ", "-")


def headings(path):
    out, seen, fence = [], {}, False
    with open(path, encoding="utf-8") as f:
        for line in f:
            if line.startswith("```"):
                fence = not fence
                continue
            m = None if fence else re.match(r"^#{1,6} (.*?)\s*#*\s*$", line)
            if m:
                a = anchor(m.group(1))
                n = seen.get(a, 0)
                seen[a] = n + 1
                out.append(a if n == 0 else f"{a}-{n}")
    return out


def titles(path):
    """Heading texts and bold leads ("**Title.**"), for quoted section names."""
    text = open(path, encoding="utf-8").read()
    ts = [m.group(1).strip() for m in re.finditer(r"^#{1,6} (.*)$", text, re.M)]
    return ts + re.findall(r"\*\*([^*]{1,300}?)\*\*", text)


def md_files():
    files = [os.path.join(ROOT, "README.md"), os.path.join(ROOT, "CHANGELOG.md")]
    for dirpath, _, names in os.walk(os.path.join(ROOT, "docs")):
        files += [os.path.join(dirpath, n) for n in names if n.endswith(".md")]
    return [f for f in files if os.path.exists(f)]


def main():
    broken, checked = [], 0
    link = re.compile(r"\]\(([^)\s]+?\.md)(#[^)\s]*)?\)")
    for f in md_files():
        text = open(f, encoding="utf-8").read()
        for m in link.finditer(text):
            target, frag = m.group(1), m.group(2)
            if re.match(r"^[a-z]+://", target):
                continue
            checked += 1
            path = os.path.normpath(os.path.join(os.path.dirname(f), target))
            line = text.count("\n", 0, m.start()) + 1
            where = f"{os.path.relpath(f, ROOT)}:{line}"
            if not os.path.exists(path):
                broken.append(f"{where}: no file {target}")
            elif frag and frag[1:] not in headings(path):
                broken.append(f"{where}: no heading {frag} in {target}")
    for b in broken:
        print(b)
    print(f"{checked} links checked, {len(broken)} broken")
    stale = quoted_sections()
    for q in stale:
        print(q)
    print(f"{len(stale)} quoted section names not found (a warning: a quote may abbreviate)")
    return 1 if broken else 0


def norm(t):
    t = re.sub(r"\n\s*(?:#+|//[!/]?|\*)?\s*", " ", t)
    return re.sub(r"\s+", " ", t.replace("`", "").replace("*", "")).strip().rstrip(".:").lower()


def quoted_sections():
    """`docs/X.md, "Title"` or `[X.md](X.md), "Title"` in docs, README and code comments."""
    pat = re.compile(r'([\w-]+\.md)\]?(?:\([^)]*\))?,?\s*(?:#+|//[!/]?|\*)?\s*"([^"]{3,200})"')
    out, cache = [], {}
    roots = ["README.md", "CHANGELOG.md", "docs", "driver/src", "kernels/src", "capi", "benches", "tests", "scripts", "fuzz"]
    for r in roots:
        base = os.path.join(ROOT, r)
        files = [base] if os.path.isfile(base) else [
            os.path.join(d, n) for d, _, ns in os.walk(base) for n in ns
            if n.endswith((".md", ".rs", ".sh", ".py", ".h", ".c", ".cpp"))]
        for f in files:
            try:
                text = open(f, encoding="utf-8").read()
            except (UnicodeDecodeError, OSError):
                continue
            for m in pat.finditer(text):
                doc, quote = m.group(1), norm(m.group(2))
                if doc in ("README.md", "CHANGELOG.md") or f.endswith("doc-links.py"):
                    continue
                path = os.path.join(ROOT, "docs", doc) if doc not in ("README.md", "CHANGELOG.md") else os.path.join(ROOT, doc)
                if not os.path.exists(path):
                    path = os.path.join(ROOT, doc)
                if not os.path.exists(path):
                    continue
                if path not in cache:
                    cache[path] = [norm(t) for t in titles(path)]
                if not any(t.startswith(quote) or quote.startswith(t) and len(t) > 8 for t in cache[path]):
                    line = text.count("\n", 0, m.start()) + 1
                    out.append(f"{os.path.relpath(f, ROOT)}:{line}: {doc}, \"{m.group(2)}\"?")
    return out


if __name__ == "__main__":
    sys.exit(main())
