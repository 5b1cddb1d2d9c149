#!/usr/bin/env python3
"""List the workspace's non-test Rust functions longer than a limit.

    tools/long_functions.py [--max N] [--tsv] [ROOT]

ROOT is the workspace (default: this script's parent's parent). Every `*.rs` file under it
is read, except those under `vendor/`, `target/`, hidden folders, `node_modules/`, and any
`tests/` folder (integration tests and the `tests` crate). Within a file, test code is left
out: items under `#[cfg(test)]` (a module, a function, an impl) and functions marked
`#[test]`.

A function's length is counted in lines from the line of its `fn` keyword to the line of
its closing brace, both included (doc comments and attributes above it are not counted). A
nested function counts within its parent and is also listed on its own when it is long.

Output: one function a line, longest first, `LINES  PATH:LINE  NAME`, or with `--tsv`
`PATH<TAB>NAME<TAB>LINE<TAB>LINES`, PATH relative to ROOT with `/` separators. The exit code
is 0 whether or not functions are listed (the caller decides what a listing means); 2 on a
usage error or a file that cannot be read.

Python 3 standard library only.
"""

from __future__ import annotations

import argparse
import os
import re
import sys
from dataclasses import dataclass

SKIP_DIRS = {"vendor", "target", "tests", "node_modules"}
RAW = re.compile(r'(?:br|cr|r)(#*)"')


@dataclass
class Function:
    path: str
    name: str
    line: int
    lines: int


def mask(src: str) -> str:
    """The source with the contents of comments, strings and char literals blanked.

    Every character inside a comment, string literal (all forms: "", b"", c"", r#""#, ...)
    or char literal becomes a space, newlines excepted, so that the line numbers and
    offsets of what is left (the code) do not move and braces inside text do not count.
    """
    out = list(src)
    n = len(src)
    i = 0

    def blank(a: int, b: int) -> None:
        for k in range(a, min(b, n)):
            if out[k] != "\n":
                out[k] = " "

    def ident_char(c: str) -> bool:
        return c.isalnum() or c == "_"

    while i < n:
        c = src[i]
        if c == "/" and i + 1 < n and src[i + 1] == "/":
            j = src.find("\n", i)
            j = n if j < 0 else j
            blank(i, j)
            i = j
            continue
        if c == "/" and i + 1 < n and src[i + 1] == "*":
            depth, j = 1, i + 2
            while j < n and depth:
                if src.startswith("/*", j):
                    depth, j = depth + 1, j + 2
                elif src.startswith("*/", j):
                    depth, j = depth - 1, j + 2
                else:
                    j += 1
            blank(i, j)
            i = j
            continue
        prev_ident = i > 0 and ident_char(src[i - 1])
        # raw strings: r"..", r#".."#, br#".."#, cr#".."#
        m = None if prev_ident else RAW.match(src, i)
        if m:
            hashes = m.group(1)
            end = src.find('"' + hashes, m.end())
            end = n if end < 0 else end + 1 + len(hashes)
            blank(m.end(), end - 1 - len(hashes))
            i = end
            continue
        if c == '"' or (not prev_ident and c in "bc" and i + 1 < n and src[i + 1] == '"'):
            j = i + 1 if c == '"' else i + 2
            while j < n and src[j] != '"':
                j += 2 if src[j] == "\\" else 1
            blank(i + (1 if c == '"' else 2), j)
            i = j + 1
            continue
        if c == "'" or (not prev_ident and c == "b" and i + 1 < n and src[i + 1] == "'"):
            q = i if c == "'" else i + 1
            # a char literal: '\..', or one character then a closing quote; else a lifetime
            if q + 1 < n and src[q + 1] == "\\":
                j = q + 3
                while j < n and src[j] != "'":
                    j += 1
                blank(q + 1, j)
                i = j + 1
                continue
            if q + 2 < n and src[q + 2] == "'" and src[q + 1] != "\n":
                blank(q + 1, q + 2)
                i = q + 3
                continue
            i = q + 1
            continue
        i += 1
    return "".join(out)


def matching(code: str, open_at: int) -> int:
    """The offset of the brace closing the one at `open_at` (len(code) if none)."""
    depth = 0
    for k in range(open_at, len(code)):
        ch = code[k]
        if ch == "{":
            depth += 1
        elif ch == "}":
            depth -= 1
            if depth == 0:
                return k
    return len(code)


def item_end(code: str, start: int) -> int:
    """Where the item starting at `start` ends: its `;`, or its body's closing brace.

    Parentheses and brackets (an attribute's, a signature's, a tuple struct's) are stepped
    over, so the first `{` or `;` outside them decides.
    """
    depth = 0
    for k in range(start, len(code)):
        ch = code[k]
        if ch in "([":
            depth += 1
        elif ch in ")]":
            depth -= 1
        elif depth == 0 and ch == ";":
            return k
        elif depth == 0 and ch == "{":
            return matching(code, k)
    return len(code)


TEST_CFG = re.compile(r"#\s*\[\s*cfg\s*\(\s*(?:test|all\s*\(\s*test\b[^\]]*\))\s*\)\s*\]")
TEST_ATTR = re.compile(r"#\s*\[\s*(?:test|tokio::test)\s*\]")
ATTR = re.compile(r"#\s*!?\s*\[")
FN = re.compile(r"\bfn\s+(r#)?([A-Za-z_][A-Za-z0-9_]*)")


def test_ranges(code: str) -> list[tuple[int, int]]:
    """Offset ranges of test-only items: `#[cfg(test)]` items and `#[test]` functions."""
    ranges = []
    for pat in (TEST_CFG, TEST_ATTR):
        for m in pat.finditer(code):
            start = m.end()
            # step over further attributes on the same item
            while True:
                rest = code[start:]
                stripped = len(rest) - len(rest.lstrip())
                a = ATTR.match(code, start + stripped)
                if not a:
                    break
                depth, k = 0, a.end() - 1
                while k < len(code):
                    if code[k] == "[":
                        depth += 1
                    elif code[k] == "]":
                        depth -= 1
                        if depth == 0:
                            break
                    k += 1
                start = k + 1
            ranges.append((m.start(), item_end(code, start)))
    return ranges


def functions(path: str, rel: str) -> list[Function]:
    with open(path, encoding="utf-8") as f:
        src = f.read()
    code = mask(src)
    excluded = test_ranges(code)
    line_starts = [0]
    for k, ch in enumerate(code):
        if ch == "\n":
            line_starts.append(k + 1)

    def line_of(offset: int) -> int:
        lo, hi = 0, len(line_starts)
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if line_starts[mid] <= offset:
                lo = mid
            else:
                hi = mid
        return lo + 1

    found = []
    for m in FN.finditer(code):
        if any(a <= m.start() <= b for a, b in excluded):
            continue
        end = item_end(code, m.end())
        if end >= len(code) or code[end] == ";":
            continue  # a declaration without a body (trait method, extern fn)
        first, last = line_of(m.start()), line_of(end)
        found.append(Function(rel, m.group(2), first, last - first + 1))
    return found


def rust_files(root: str):
    for dirpath, dirnames, filenames in os.walk(root):
        dirnames[:] = sorted(
            d for d in dirnames if d not in SKIP_DIRS and not d.startswith(".")
        )
        for name in sorted(filenames):
            if name.endswith(".rs"):
                full = os.path.join(dirpath, name)
                yield full, os.path.relpath(full, root).replace(os.sep, "/")


def main(argv: list[str]) -> int:
    here = os.path.dirname(os.path.abspath(__file__))
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--max", type=int, default=150, help="list functions longer than this (lines)")
    p.add_argument("--tsv", action="store_true", help="PATH<TAB>NAME<TAB>LINE<TAB>LINES")
    p.add_argument("root", nargs="?", default=os.path.dirname(here))
    args = p.parse_args(argv)
    listed = []
    for full, rel in rust_files(args.root):
        try:
            listed += [f for f in functions(full, rel) if f.lines > args.max]
        except (OSError, UnicodeDecodeError) as e:
            print(f"long_functions: {rel}: {e}", file=sys.stderr)
            return 2
    listed.sort(key=lambda f: (-f.lines, f.path, f.line))
    for f in listed:
        if args.tsv:
            print(f"{f.path}\t{f.name}\t{f.line}\t{f.lines}")
        else:
            print(f"{f.lines:6}  {f.path}:{f.line}  {f.name}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
