"""Draw docs/images/architecture.png (and .svg): froude's layers, the modules in each, and the imports
between layers, read from the source by scripts/layers.py (the same ``ast`` parse as tests/test_layers.py,
imports inside functions counted), so the picture is the code's, not a wish.

Run:  python docs/make_architecture.py
Prints the layer graph (pasted into docs/architecture.md), every import that points up a layer and every
import circle (tests/test_layers.py fails on a new one).
"""
from __future__ import annotations

import math
import sys
from collections import Counter
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "scripts"))
from layers import LAYERS, ORDER, all_imports, circles, graph_text, layer_edges, layer_of, modules, upward  # noqa: E402


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
        short = sorted(n.split(".", 1)[1] if "." in n and n.split(".")[0] == layer else n for n in by_layer[layer])
        groups: dict[str, list[str]] = {}  # a sub-package's modules as one entry, so that a box holds its layer
        for n in short:
            head, _, rest = n.partition(".")
            groups.setdefault(head, []).extend([rest] if rest else [])
        names = ", ".join(f"{h}.{{{', '.join(m)}}}" if len(m) > 1 else f"{h}.{m[0]}" if m else h
                          for h, m in groups.items())
        lines, line = [], ""
        for word in names.split(" "):
            if len(line) + len(word) > (120 if len(names) <= 240 else 165):  # a long list: two smaller lines
                lines.append(line)
                line = ""
            line += word + " "
        lines.append(line)
        ax.text(x0 + 0.15, y + 0.12, "\n".join(lines), fontsize=7.4 if len(names) <= 240 else 6.0, va="bottom",
                family="monospace",
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
    imps = all_imports()
    print(graph_text(imps, mods))
    up, rings = upward(imps), circles(imps)
    for line in up + rings:
        print(line)
    out = HERE / "images" / "architecture.png"
    out.parent.mkdir(exist_ok=True)
    draw(mods, layer_edges(imps), out)
    print(f"wrote {out} and {out.with_suffix('.svg')}; {len(up)} upward import(s), {len(rings)} circle(s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
