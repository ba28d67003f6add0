"""Branches on a study world outside app/worlds/: the World protocol should make them needless.

    python -m tools.world_branches

A branch is an `if`, conditional expression, comprehension filter, `while` or `match`
whose condition mentions a world's name or a world-only piece of geometry (lanes, goals,
obstacles). Drawing loops over a scene's parts are not branches. Prints each one found
(exit 1 if any).
"""

import ast
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCANNED = ("app", "analysis")
ALLOWED = ("app/worlds/",)
WORLD_WORDS = re.compile(r"\blanes\b|\bgoals\b|\bobstacles\b|is_highway|is_obstacle"
                         r"|['\"](highway|obstacle)['\"]")


def conditions(tree: ast.AST):
    """Every condition node of a branch in `tree`, with its line."""
    for node in ast.walk(tree):
        if isinstance(node, (ast.If, ast.IfExp, ast.While)):
            yield node.test
        elif isinstance(node, ast.comprehension):
            yield from node.ifs
        elif isinstance(node, ast.Match):
            yield node.subject
            for case in node.cases:
                yield case.pattern


def world_branches() -> list[str]:
    """`path:line: condition` for every branch on a world outside the allowed folders."""
    found = []
    for pkg in SCANNED:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            if rel.startswith(ALLOWED):
                continue
            source = path.read_text()
            for cond in conditions(ast.parse(source, filename=rel)):
                text = ast.get_source_segment(source, cond) or ""
                if WORLD_WORDS.search(text):
                    found.append(f"{rel}:{cond.lineno}: {text}")
    return found


def main() -> None:
    """Print every world branch; exit 1 if there is one."""
    found = world_branches()
    print(f"{len(found)} world branch(es) outside {', '.join(ALLOWED)}")
    for line in found:
        print("  " + line)
    sys.exit(1 if found else 0)


if __name__ == "__main__":
    main()
