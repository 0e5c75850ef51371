"""List the functions over 80 lines and whether a "# Long because" comment above them (or at their start)
says why. tests/test_lint.py fails on any without a reason.

    python scripts/long_functions.py [src/froude]
"""
from __future__ import annotations

import ast
import pathlib
import sys

MAX_LINES = 80


def long_functions(root: pathlib.Path) -> list[tuple[int, str, str, bool]]:
    """[(length in lines, "file:line", name, reason given)] of every function over MAX_LINES under root."""
    rows = []
    for p in sorted(root.rglob("*.py")):
        lines = p.read_text().splitlines()
        for n in ast.walk(ast.parse("\n".join(lines))):
            if not isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            length = n.end_lineno - n.lineno + 1
            if length <= MAX_LINES:
                continue
            top = n.decorator_list[0].lineno - 1 if n.decorator_list else n.lineno - 1
            while top > 0 and lines[top - 1].lstrip().startswith("#"):  # the comment block right above counts
                top -= 1
            head = "\n".join(lines[top:n.lineno + 2]).lower()
            why = "long because" in head or "# long:" in head
            rows.append((length, f"{p.relative_to(root.parent)}:{n.lineno}", n.name, why))
    return sorted(rows, reverse=True)


def main() -> int:
    rows = long_functions(pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else "src/froude"))
    for length, where, name, why in rows:
        print(f"{length:4d}  {'why given' if why else 'NO REASON':9s}  {where}  {name}")
    print(f"{len(rows)} functions over {MAX_LINES} lines, {sum(not r[3] for r in rows)} without a reason")
    return 0


if __name__ == "__main__":
    sys.exit(main())
