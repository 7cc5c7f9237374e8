#!/usr/bin/env python3
"""Checks the house rules ARCHITECTURE.md states: no source file over 800 lines outside tests,
and no circle of imports between the files of a crate (`use crate::...`, `use super::...`).

    python3 scripts/check-structure.py

Exits 1 and names the offenders when a rule is broken. Imports are read as text: a file's
imports are the `crate::` and `super::` paths it names, resolved to the deepest module that has
a file of its own. A module's own `mod.rs` (or `lib.rs`) importing its children is how Rust
exposes them and is not counted as one half of a circle when the child imports its parent's
items: the circles this finds are between files side by side or far apart.
"""

import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
MAX_LINES = 800
PATH = re.compile(r"\b(crate|super)((?:::[A-Za-z_][A-Za-z0-9_]*)+)")


def crate_sources():
    for manifest in sorted(ROOT.glob("**/Cargo.toml")):
        if "target" in manifest.parts or manifest.parent == ROOT:
            continue
        src = manifest.parent / "src"
        if src.is_dir():
            yield src


def module_of(src: Path, file: Path):
    parts = list(file.relative_to(src).with_suffix("").parts)
    if parts[-1] in ("mod", "lib", "main"):
        parts = parts[:-1]
    if parts and parts[0] == "bin":
        return None
    return tuple(parts)


def strip_comments(text: str) -> str:
    return "\n".join(line.split("//", 1)[0] for line in text.splitlines())


def main() -> int:
    problems = []
    for src in crate_sources():
        files = {}
        for file in sorted(src.rglob("*.rs")):
            lines = len(file.read_text(encoding="utf-8").splitlines())
            if lines > MAX_LINES:
                problems.append(f"{file.relative_to(ROOT)}: {lines} lines (limit {MAX_LINES})")
            module = module_of(src, file)
            if module is not None:
                files[module] = file
        edges = {module: set() for module in files}
        for module, file in files.items():
            text = strip_comments(file.read_text(encoding="utf-8"))
            # Inline test modules import what they test; they are not part of the structure.
            text = text.split("#[cfg(test)]", 1)[0]
            is_mod_file = file.stem in ("mod", "lib", "main")
            for anchor, rest in PATH.findall(text):
                names = [n for n in rest.split("::") if n]
                if anchor == "crate":
                    base = ()
                else:
                    base = module if is_mod_file else module[:-1]
                    while names and names[0] == "super":
                        base = base[:-1]
                        names = names[1:]
                target = base
                for name in names:
                    if base + (name,) in files or (target + (name,)) in files:
                        target = target + (name,)
                    else:
                        break
                if target != module and target in files:
                    # A parent module reaching into its own children is its front door.
                    if module == target[: len(module)]:
                        continue
                    # A child naming its ancestor's items is the other half of that door.
                    if target == module[: len(target)]:
                        continue
                    edges[module].add(target)
        for cycle in find_cycles(edges):
            names = " -> ".join(str(files[m].relative_to(ROOT)) for m in cycle + [cycle[0]])
            problems.append(f"import circle: {names}")
    for problem in problems:
        print(problem)
    return 1 if problems else 0


def find_cycles(edges):
    """One representative cycle per strongly connected component of more than one file."""
    index, low, stack, on_stack, result = {}, {}, [], set(), []
    counter = [0]

    def visit(node):
        index[node] = low[node] = counter[0]
        counter[0] += 1
        stack.append(node)
        on_stack.add(node)
        for nxt in edges[node]:
            if nxt not in index:
                visit(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in on_stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                result.append(sorted(component))

    sys.setrecursionlimit(10000)
    for node in edges:
        if node not in index:
            visit(node)
    return result


if __name__ == "__main__":
    sys.exit(main())
