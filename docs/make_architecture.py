"""Draw docs/images/architecture.png (and .svg): froude's layers, the modules in each, and the imports
between layers, read from the source (``ast``), so the picture is the code's, not a wish.

Run:  python docs/make_architecture.py
Prints every import that points up a layer (there should be none) and the layer of every module.
"""
from __future__ import annotations

import ast
import math
import sys
from collections import Counter
from pathlib import Path

HERE = Path(__file__).resolve().parent
PKG = HERE.parent / "src" / "froude"

#: Bottom to top: a layer may import the ones below it, never above. (layer, what it holds)
LAYERS = [
    ("core", "quaternions, skeleton, motion, FK and Jacobians; constants, errors"),
    ("io", "BVH, glTF, per-frame tables, atomic writes, JSON"),
    ("body", "body model (de Leva), joint roles, gait and contacts, characters, conventions, the take"),
    ("machine", "§4-5: units, dynamics, orbits, forces, fit, speed (§5.2), transition table and planner (§5.3)"),
    ("synthesis", "§6 input: reference cycle, time warp, IK targets"),
    ("ik", "§6: IK tasks, the batched whole-body solver and its kernels, the correction policy"),
    ("report", "the physics report (metrics) and plots/renders (viz)"),
    ("pipeline", "prepare / scale / accelerate / naive: orchestration; the public verbs (api)"),
    ("apps", "command line, studio, batch, demo, signals"),
]
#: Top-level modules (src/froude/X.py) and the layer they belong to; packages are their own layer.
TOP_LEVEL = {
    "constants": "core", "errors": "core", "samples": "io", "speed_goal": "machine", "metrics": "report",
    "viz": "report", "pipeline": "pipeline", "prepared": "pipeline", "result": "pipeline", "naive": "pipeline",
    "speed_range": "pipeline", "speed_change": "pipeline", "clipinfo": "pipeline", "path_report": "report",
    "api": "pipeline", "__init__": "pipeline", "__main__": "apps",
    "characters": "body", "conventions": "body", "gait": "body", "presets": "body", "quat": "core",
    "skeleton": "core", "motion": "core", "kinematics": "core", "synthesis": "synthesis", "ik": "ik",
    "batch": "apps", "demo": "apps", "cli": "apps", "studio": "apps", "body": "body",
}
ORDER = {name: i for i, (name, _) in enumerate(LAYERS)}


def layer_of(module: str) -> str:
    """'froude.machine.fit' → 'machine'; a top-level module by TOP_LEVEL (unknown ones: 'pipeline')."""
    parts = module.split(".")
    head = parts[1] if len(parts) > 1 else "__init__"
    return head if head in ORDER else TOP_LEVEL.get(head, "pipeline")


def modules() -> dict[str, Path]:
    out = {}
    for p in sorted(PKG.rglob("*.py")):
        rel = p.relative_to(PKG.parent).with_suffix("")
        name = ".".join(rel.parts[:-1] if rel.name == "__init__" else rel.parts)
        out[name] = p
    return out


def imports(name: str, path: Path) -> set[str]:
    """froude modules imported by one module (absolute and relative, at any depth in the file)."""
    pkg = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = pkg.split(".")[: len(pkg.split(".")) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            if mod.startswith("froude"):
                found.add(mod)
                found.update(f"{mod}.{a.name}" for a in node.names)
        elif isinstance(node, ast.Import):
            found.update(a.name for a in node.names if a.name.startswith("froude"))
    return found


def edges(mods: dict[str, Path]) -> tuple[Counter, list[str]]:
    """(Counter of (from layer, to layer) module imports, the upward imports as text)."""
    count: Counter = Counter()
    upward = []
    for name, path in mods.items():
        src = layer_of(name)
        for target in imports(name, path):
            if target not in mods:
                continue
            dst = layer_of(target)
            if dst != src:
                count[(src, dst)] += 1
                if ORDER[dst] > ORDER[src]:
                    upward.append(f"{name} ({src}) imports {target} ({dst})")
    return count, sorted(set(upward))


def draw(mods: dict[str, Path], count: Counter, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import FancyArrowPatch, FancyBboxPatch

    by_layer: dict[str, list[str]] = {n: [] for n in ORDER}
    for name, path in mods.items():
        if path.name == "__init__.py" and name != "froude":
            continue  # a package's own __init__ (re-exports): its modules are listed
        short = name.removeprefix("froude.").removeprefix("froude") or "__init__"
        by_layer[layer_of(name)].append(short)
    box_h, gap, x0, w = 0.9, 0.35, 2.2, 9.0
    fig, ax = plt.subplots(figsize=(12.5, len(LAYERS) * (box_h + gap) * 0.78 + 0.6), dpi=110)
    y_of = {}
    for i, (layer, what) in enumerate(LAYERS):
        y = i * (box_h + gap)
        y_of[layer] = y
        shade = plt.cm.Blues(0.15 + 0.55 * i / (len(LAYERS) - 1))
        ax.add_patch(FancyBboxPatch((x0, y), w, box_h, boxstyle="round,pad=0.02,rounding_size=0.08",
                                    fc=shade, ec="#30507a", lw=1.2))
        ax.text(x0 + 0.15, y + box_h - 0.2, layer, fontsize=12, weight="bold", va="top", color="#10243f")
        ax.text(x0 + 1.45, y + box_h - 0.22, what, fontsize=8.2, va="top", color="#10243f", style="italic")
        names = ", ".join(sorted(n.split(".", 1)[1] if "." in n and n.split(".")[0] == layer else n
                                 for n in by_layer[layer]))
        lines, line = [], ""
        for word in names.split(" "):
            if len(line) + len(word) > 120:
                lines.append(line)
                line = ""
            line += word + " "
        lines.append(line)
        ax.text(x0 + 0.15, y + 0.12, "\n".join(lines), fontsize=7.4, va="bottom", family="monospace",
                color="#1b1b1b")
    # imports between layers on the left: one arc per (from, to), width ~ log of the module imports
    for k, ((src, dst), n) in enumerate(sorted(count.items(), key=lambda e: (ORDER[e[0][0]], ORDER[e[0][1]]))):
        up = ORDER[dst] > ORDER[src]
        ys, yd = y_of[src] + box_h * 0.5, y_of[dst] + box_h * 0.5
        rad = 0.25 + 0.5 * (k % 5) / 5
        ax.add_patch(FancyArrowPatch((x0, ys), (x0, yd), connectionstyle=f"arc3,rad={rad}",
                                     arrowstyle="-|>", mutation_scale=9, lw=0.5 + 0.5 * math.log2(1 + n),
                                     color="#c0392b" if up else "#5d6d7e", alpha=0.75))
    ax.text(x0 + w, -0.3, "arcs: imports between layers (width ~ log of the count); red: an import up a layer",
            fontsize=7.5, ha="right", va="top", color="#444444")
    ax.set_xlim(-1.2, x0 + w + 0.2)
    ax.set_ylim(-0.6, len(LAYERS) * (box_h + gap))
    ax.axis("off")
    ax.set_title("froude: layers (bottom → top), modules, and the imports between them", fontsize=12)
    fig.tight_layout()
    for suffix in (".png", ".svg"):
        fig.savefig(out.with_suffix(suffix))
    plt.close(fig)


def main() -> int:
    mods = modules()
    count, upward = edges(mods)
    for name in mods:
        print(f"{layer_of(name):10s} {name}")
    for line in upward:
        print("UPWARD:", line)
    out = HERE / "images" / "architecture.png"
    out.parent.mkdir(exist_ok=True)
    draw(mods, count, out)
    print(f"wrote {out} and {out.with_suffix('.svg')}; {len(upward)} upward import(s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
