"""List the functions over 80 lines and whether a "# Long because" comment above them says why.

    python scripts/long_functions.py [src/froude]
"""
import ast, pathlib, sys
root = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else "src/froude")
rows = []
for p in sorted(root.rglob("*.py")):
    text = p.read_text()
    lines = text.splitlines()
    for n in ast.walk(ast.parse(text)):
        if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)):
            length = n.end_lineno - n.lineno + 1
            if length > 80:
                start = n.decorator_list[0].lineno if n.decorator_list else n.lineno
                head = "\n".join(lines[max(0, start - 4):n.lineno + 2])
                why = "long because" in head.lower() or "# long:" in head.lower()
                rows.append((length, f"{p.relative_to(root.parent)}:{n.lineno}", n.name, why))
for length, where, name, why in sorted(rows, reverse=True):
    print(f"{length:4d}  {'why given' if why else 'NO REASON':9s}  {where}  {name}")
print(f"{len(rows)} functions over 80 lines, {sum(not r[3] for r in rows)} without a reason")
