#!/usr/bin/env python3
"""Import circles between the files of one crate.

For every crate of the workspace (a folder with Cargo.toml under shared-types/, libs/,
processes/, tools/, tests/), each top-level file of `src/` is a module; a file that names
`crate::m`, `super::m` (from a top-level file) or `m::` of a sibling module it declared
uses m. Any circle in that graph is printed, one per line, as `crate: a -> b -> a`, and
the exit status is 1; no circle, exit 0 and one line saying how many crates and files
were read.

    python3 tools/module_cycles.py [ROOT]

Only the files' code counts: comments and strings are stripped first, and a `#[cfg(test)]`
module at the end of a file is cut off, since test code may reach anywhere.
"""

import re
import sys
from pathlib import Path


def strip(text: str) -> str:
    """The code of a Rust file without comments, string literals and its test module."""
    text = re.sub(r"//[^\n]*", "", text)
    text = re.sub(r"/\*.*?\*/", "", text, flags=re.S)
    text = re.sub(r'r#*"(?:.|\n)*?"#*', '""', text)
    text = re.sub(r'"(?:\\.|[^"\\])*"', '""', text)
    cut = re.search(r"#\[cfg\(test\)\]\s*mod\s+tests", text)
    return text[: cut.start()] if cut else text


def crate_graph(src: Path) -> dict[str, set[str]]:
    modules = {p.stem: strip(p.read_text()) for p in src.glob("*.rs")}
    roots = {"lib", "main"}
    names = {m for m in modules if m not in roots}
    graph: dict[str, set[str]] = {m: set() for m in modules}
    for m, code in modules.items():
        for other in names - {m}:
            pattern = rf"\b(?:crate|super)::{other}\b"
            if m in roots:
                # The crate root declares every module; only its uses of them are edges
                # out of it, and nothing imports the root by name.
                continue
            if re.search(pattern, code):
                graph[m].add(other)
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Each elementary circle once, starting from its smallest name."""
    found: list[list[str]] = []
    seen: set[tuple[str, ...]] = set()

    def walk(start: str, node: str, path: list[str]) -> None:
        for nxt in sorted(graph.get(node, ())):
            if nxt == start:
                key = tuple(path)
                if key not in seen:
                    seen.add(key)
                    found.append(path + [start])
            elif nxt not in path and nxt > start:
                walk(start, nxt, path + [nxt])

    for start in sorted(graph):
        walk(start, start, [start])
    return found


def main() -> int:
    root = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parents[1]
    crates = 0
    files = 0
    bad = []
    for manifest in sorted(root.glob("**/Cargo.toml")):
        rel = manifest.relative_to(root)
        if rel.parts[0] in {"target", "vendor"} or "node_modules" in rel.parts:
            continue
        src = manifest.parent / "src"
        if not src.is_dir():
            continue
        crates += 1
        graph = crate_graph(src)
        files += len(graph)
        for circle in cycles(graph):
            bad.append(f"{manifest.parent.relative_to(root)}: {' -> '.join(circle)}")
    for line in bad:
        print(line)
    if bad:
        print(f"{len(bad)} import circle(s) between files of one crate", file=sys.stderr)
        return 1
    print(f"no import circle: {files} files of {crates} crates read")
    return 0


if __name__ == "__main__":
    sys.exit(main())
