"""A package as a tree, one line per module: its name and what its docstring says first.

    python -m tools.module_tree [app]
"""

import ast
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def summary(path: Path) -> str:
    """The first paragraph of a module's docstring on one line ('' if it has none)."""
    doc = ast.get_docstring(ast.parse(path.read_text())) or ""
    return " ".join(doc.strip().split("\n\n")[0].split())


def tree_lines(folder: Path, depth: int = 0) -> list[str]:
    """Indented lines for `folder`: its modules first, then each subpackage."""
    pad = "  " * depth
    lines = []
    for path in sorted(folder.glob("*.py")):
        if path.name != "__init__.py":
            lines.append(f"{pad}{path.name:<24} {summary(path)}")
    for sub in sorted(p for p in folder.iterdir() if p.is_dir() and (p / "__init__.py").exists()):
        lines.append(f"{pad}{sub.name}/{'':<{23 - len(sub.name)}} {summary(sub / '__init__.py')}")
        lines += tree_lines(sub, depth + 1)
    return lines


def main() -> None:
    """Print the tree of the package named on the command line (default: app)."""
    package = sys.argv[1] if len(sys.argv) > 1 else "app"
    if not (ROOT / package / "__init__.py").is_file():
        sys.exit(f"package: {package!r} is not a package under {ROOT} (e.g. app, analysis)")
    print(f"{package}/")
    print("\n".join("  " + line for line in tree_lines(ROOT / package)))


if __name__ == "__main__":
    main()
