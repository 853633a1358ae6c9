"""Draw docs/architecture.svg: the layers of docs/architecture.md and the imports between them.

The layers are read from the table in docs/architecture.md and the imports from the code, with
the walker of tests/test_architecture.py, so the picture shows what the check enforces. Only
direct dependencies are drawn (an import implied by a chain of arrows is left out); ``errors``,
which every layer imports, has none. Dotted arrows: the forward model's package (``model``), which
fitting, sampling and diagnosis will import once it lands.

Run from the repository root: ``python docs/architecture_picture.py``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.patches import FancyArrowPatch, FancyBboxPatch  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
from test_architecture import DOC, edges, module_name, read_layers, unit  # noqa: E402

PLANNED = [("fitting", "model"), ("sampling", "model"), ("diagnosis", "model"), ("model", "render")]
BOX_W, BOX_H, ROW_H = 1.5, 0.42, 0.8
# x of each box's centre, chosen so that long arrows pass beside the boxes between their ends.
COLUMN = {"cli": 2.0, "abs": 5.6, "studies": 4.4, "sampling": 1.0, "diagnosis": 3.0,
          "fitting": 1.0, "runs": 4.2, "model": 2.0, "simulate": 3.6, "render": 2.0,
          "scene": 1.2, "report": 4.2, "brdf": 0.8, "metrics": 4.2, "acquisition": 6.0,
          "probe": 7.8, "io": 2.4, "params": 1.0, "colour": 3.2, "camera": 6.6, "errors": 2.0,
          "pools": 6.2, "reassembly": 5.2, "editing": 6.4, "resynthesis": 5.4, "appearance": 7.0}


def direct(pairs: set[tuple[str, str]]) -> list[tuple[str, str]]:
    """The pairs not implied by a longer path (transitive reduction of an acyclic graph)."""
    below = {a: {b for x, b in pairs if x == a} for a, _ in pairs}

    def reach(node: str, seen: set[str]) -> set[str]:
        for nxt in below.get(node, ()):
            if nxt not in seen:
                seen.add(nxt)
                reach(nxt, seen)
        return seen

    return sorted((a, b) for a, b in pairs
                  if not any(b in reach(c, {c}) for c in below[a] if c != b))


def main() -> None:
    layers = read_layers(DOC.read_text(encoding="utf-8"))
    rows: dict[int, list[str]] = {}
    for name, layer in layers.items():
        rows.setdefault(layer, []).append(name)
    centre = {}
    for layer, names in rows.items():
        free = 0.0
        for name in names:  # hand-placed columns; a package added to the table goes to the right
            x = COLUMN.get(name)
            if x is None:
                x = max([free] + [c[0] for n, c in centre.items() if c[1] == layer * ROW_H]) + BOX_W + 0.3
            centre[name] = (x, layer * ROW_H)
            free = x
    width = max(x for x, _ in centre.values()) + BOX_W
    pairs = {(a, b) for _, _, a, b in edges() if b != "errors" and a != "abs"}
    drawn = direct(pairs | set(PLANNED))

    top = max(rows) * ROW_H
    fig, ax = plt.subplots(figsize=(width * 0.9 + 1.2, (top + ROW_H) * 0.9 + 0.4))
    for layer in rows:
        ax.text(-0.3, layer * ROW_H, str(layer), ha="right", va="center", fontsize=9, color="0.45")
    for layer in rows:  # a band per layer: imports cross bands downward only
        if layer % 2 == 0:
            ax.axhspan(layer * ROW_H - ROW_H / 2, layer * ROW_H + ROW_H / 2, color="0.96", zorder=0)
    for a, b in drawn:
        (xa, ya), (xb, yb) = centre[a], centre[b]
        # Arrows over more than one layer bow sideways, so that they pass beside the boxes between.
        span = round((ya - yb) / ROW_H)
        bow = 0.0 if span <= 1 else (0.35 if xb >= xa else -0.35)
        ax.add_patch(FancyArrowPatch((xa, ya - BOX_H / 2), (xb, yb + BOX_H / 2), arrowstyle="-|>",
                                     mutation_scale=9, lw=0.7, color="0.35" if span <= 1 else "0.55",
                                     connectionstyle=f"arc3,rad={bow}", zorder=1,
                                     linestyle=":" if (a, b) in PLANNED else "-"))
    present = {unit(module_name(path)) for path in (ROOT / "abs").rglob("*.py")}
    for name, (x, y) in centre.items():
        planned = name not in present
        ax.add_patch(FancyBboxPatch((x - BOX_W / 2, y - BOX_H / 2), BOX_W, BOX_H,
                                    boxstyle="round,pad=0.02,rounding_size=0.08",
                                    fc="white" if planned else "#e8eef7", ec="0.3",
                                    ls=":" if planned else "-", lw=0.9, zorder=2))
        ax.text(x, y, name, ha="center", va="center", fontsize=10, family="monospace", zorder=3)
    ax.text(-0.3, top + ROW_H * 0.65, "layer", ha="right", va="center", fontsize=9, color="0.45")
    ax.set_xlim(-0.9, width)
    ax.set_ylim(-ROW_H * 0.6, top + ROW_H * 0.9)
    ax.axis("off")
    plt.rcParams["svg.fonttype"] = "none"  # text stays text (searchable, small)
    plt.rcParams["svg.hashsalt"] = "abs"  # the same picture gives the same file
    fig.savefig(ROOT / "docs" / "architecture.svg", bbox_inches="tight", metadata={"Date": None})


if __name__ == "__main__":
    main()
