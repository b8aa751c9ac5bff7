"""Draw the layers of seqrun and the imports between them: docs/layers.svg.

    .venv/bin/python tools/draw_layers.py           # write docs/layers.svg
    .venv/bin/python tools/draw_layers.py --check   # exit 1 if the picture's layers are not today's

The layers are the table of docs/architecture.md (the one tests/test_architecture.py
enforces), bottom to top; each folder of ``seqrun/`` is one box, each module directly in
``seqrun/`` too. The arrows are read from the code: every import between two boxes (at a
module's top, inside a function, or for the type checker only) makes one arrow. Left out,
to keep the picture readable: the arrows into the base layer (every layer uses it) and an
arrow that a longer way down already implies (cli -> arm when cli -> service -> arm).
An arrow that runs back up (to a later layer of the table) is drawn in red.

The picture carries the list of every box and arrow it was drawn from. ``--check`` compares
only what the picture is for with the code's today (no drawing, no matplotlib): which box
stands in which layer, and every arrow that runs back up. A new module in a folder or a new
import downwards leaves the picture true in what it shows (the layers), so the picture is
redrawn when the layers change, not at every commit; ``tests/test_layer_picture.py`` fails
when a box moves, appears or leaves, or an arrow runs back up.
"""

from __future__ import annotations

import argparse
import ast
import fnmatch
import re
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "seqrun"
DOC = ROOT / "docs" / "architecture.md"
PICTURE = ROOT / "docs" / "layers.svg"
#: Where the picture keeps the graph it was drawn from (SVG metadata, dc:description).
GRAPH_RE = re.compile(r"<dc:description>(.*?)</dc:description>", re.S)


# --------------------------------------------------------------------------- the graph
def layer_table(text: str) -> list[tuple[str, list[str]]]:
    """The (layer, module patterns) rows of the doc's "Layers" table, in order."""
    section = text.split("## Layers", 1)[1].split("\n## ", 1)[0]
    rows = []
    for line in section.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) == 2 and cells[1].startswith("`"):
            rows.append((cells[0], re.findall(r"`([^`]+)`", cells[1])))
    return rows


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def imports_of(path: Path, name: str, *, type_checking: bool = True) -> set[str]:
    """Every module ``path`` (module ``name``) imports, wherever in its code; without
    ``type_checking``, not those inside ``if TYPE_CHECKING`` (an import for the type checker
    is an arrow of the design as much as any other: the picture and the circle check
    count it)."""
    is_package = path.name == "__init__.py"
    found: set[str] = set()

    class Imports(ast.NodeVisitor):
        def visit_If(self, node: ast.If) -> None:
            if "TYPE_CHECKING" in ast.unparse(node.test) and not type_checking:
                for child in node.orelse:
                    self.visit(child)
            else:
                self.generic_visit(node)

        def visit_Import(self, node: ast.Import) -> None:
            found.update(alias.name for alias in node.names)

        def visit_ImportFrom(self, node: ast.ImportFrom) -> None:
            if node.level:
                base = name.split(".") if is_package else name.split(".")[:-1]
                base = base[:len(base) - (node.level - 1)]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            found.add(module)
            found.update(f"{module}.{alias.name}" for alias in node.names)

    Imports().visit(ast.parse(path.read_text(encoding="utf-8")))
    return found


def room_of(module: str) -> str | None:
    """The box a module is drawn in: its folder under seqrun/, or itself (None: the
    package's own __init__, which imports nothing)."""
    parts = module.split(".")
    if len(parts) == 1:
        return None
    return f"{parts[1]}/" if (PACKAGE / parts[1]).is_dir() else f"{parts[1]}.py"


class Graph:
    """The layers, the boxes in each and the arrows between boxes, read from the tree."""

    def __init__(self) -> None:
        self.layers = layer_table(DOC.read_text(encoding="utf-8"))
        modules = {module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}
        self.members: dict[str, list[str]] = {}   # box -> its modules' names
        self.says: dict[str, str] = {}            # box (a module) -> its docstring's start
        self.layer: dict[str, int] = {}           # box -> index in the table
        for module, path in modules.items():
            room = room_of(module)
            if room is None:
                continue
            short = module.removeprefix("seqrun.")
            (layer,) = {i for i, (_, patterns) in enumerate(self.layers)
                        if any(fnmatch.fnmatchcase(short, p) for p in patterns)}
            if self.layer.setdefault(room, layer) != layer:
                raise SystemExit(f"{room} spans two layers of docs/architecture.md")
            self.members.setdefault(room, [])
            if room.endswith("/"):
                if module != f"seqrun.{room.rstrip('/')}":
                    self.members[room].append(module.rsplit(".", 1)[-1])
            else:
                doc = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8"))) or ""
                self.says[room] = doc.split("\n\n", 1)[0].replace("\n", " ").replace("``", "")
        self.edges: set[tuple[str, str]] = set()
        for module, path in modules.items():
            source = room_of(module)
            for target in imports_of(path, module):
                while target and target not in modules:
                    target = target.rpartition(".")[0]
                room = room_of(target) if target else None
                if source and room and room != source:
                    self.edges.add((source, room))

    def upward(self, edge: tuple[str, str]) -> bool:
        return self.layer[edge[1]] > self.layer[edge[0]]

    def drawn(self) -> list[tuple[str, str]]:
        """The arrows drawn: not into the base layer, and none that a longer way implies."""
        kept = {e for e in self.edges if self.layer[e[1]] != 0}  # 0: the base layer
        out: dict[str, set[str]] = {}  # the ways down (an arrow back up implies nothing)
        for a, b in kept:
            if not self.upward((a, b)):
                out.setdefault(a, set()).add(b)

        def reaches(start: str, goal: str, skip: tuple[str, str]) -> bool:
            seen, stack = {start}, [start]
            while stack:
                here = stack.pop()
                for there in out.get(here, ()):
                    if (here, there) == skip or there in seen:
                        continue
                    if there == goal:
                        return True
                    seen.add(there)
                    stack.append(there)
            return False

        return sorted(e for e in kept if self.upward(e) or not reaches(e[0], e[1], e))

    def summary(self) -> str:
        """What the picture shows, as text: the layers with their boxes, and every arrow."""
        lines = []
        for i, (name, _) in enumerate(self.layers):
            boxes = sorted(r for r, layer in self.layer.items() if layer == i)
            lines.append(f"layer {name}: {' '.join(boxes)}")
        lines += [f"box {room}: {' '.join(sorted(modules))}"
                  for room, modules in sorted(self.members.items()) if room.endswith("/")]
        lines += [f"arrow {a} -> {b}{' (back up)' if self.upward((a, b)) else ''}"
                  for a, b in sorted(self.edges)]
        return "\n".join(lines)

    def layering(self) -> str:
        """What ``--check`` holds the picture to: the layers' boxes and the arrows back up."""
        return layering_of(self.summary())


def layering_of(summary: str) -> str:
    """The lines of a picture's summary that must be today's (see the module's docstring)."""
    return "\n".join(line for line in summary.splitlines()
                     if line.startswith("layer ") or line.endswith("(back up)"))


# --------------------------------------------------------------------------- the picture
BAND = 1.75          # height of a layer's band
BOX = 1.05           # height of a box
WIDTH = 17.0         # width of the boxes' area
LEFT = 2.3           # the layer names' column
GAP = 0.25           # between two boxes
NAME_CHAR = 0.112    # width of a character of a box's name (8.5 pt bold, the figure's scale)
TEXT_CHAR = 0.075    # ... of the text under it (5.6 pt)
PAD = 0.16           # a box's inner margin, both sides


def _label(graph: Graph, room: str) -> str:
    """What a box says under its name: a folder's modules, a module's first words."""
    return ", ".join(sorted(graph.members[room])) if room.endswith("/") else graph.says[room]


def _width(graph: Graph, room: str) -> tuple[float, float]:
    """(the least width, the width wished for: the text under the name in 2-3 lines)."""
    least = NAME_CHAR * len(room) + PAD
    return least, max(least, min(7.0, TEXT_CHAR * len(_label(graph, room)) / 2.5 + PAD))


def _label_lines(text: str, chars: int) -> list[str]:
    lines = textwrap.wrap(text, max(chars, 12))
    return lines[:4] if len(lines) <= 4 else lines[:3] + [lines[3][:-1] + "…"]


def layout(graph: Graph) -> dict[str, tuple[float, float, float]]:
    """Box -> (x, y, width), bands bottom-up; in each band the boxes are ordered by where
    the boxes below that they import stand (fewer crossings)."""
    placed: dict[str, tuple[float, float, float]] = {}
    drawn = graph.drawn()
    for i in range(len(graph.layers)):
        boxes = [r for r, layer in graph.layer.items() if layer == i]

        def below(room: str) -> float:
            xs = [placed[b][0] + placed[b][2] / 2 for a, b in drawn if a == room and b in placed]
            xs += [placed[b][0] + placed[b][2] / 2 for a, b in graph.edges
                   if a == room and b in placed and not xs]
            return sum(xs) / len(xs) if xs else WIDTH / 2

        same = {(a, b) for a, b in graph.edges if a in boxes and b in boxes}
        # a box that another of its band imports stands to the right of it
        depth = {r: 0 for r in boxes}
        for _ in boxes:
            for a, b in same:
                depth[b] = max(depth[b], depth[a] + 1)
        boxes.sort(key=lambda r: (below(r) + 0.01 * depth[r] if len(boxes) > 4
                                  else depth[r] - 0.001 * below(r), r))
        least = {r: _width(graph, r)[0] for r in boxes}
        wished = {r: _width(graph, r)[1] for r in boxes}
        room_left = WIDTH - GAP * (len(boxes) - 1) - sum(least.values())
        extra = sum(wished[r] - least[r] for r in boxes)
        share = min(1.0, room_left / extra) if extra > 0 else 0.0
        width = {r: least[r] + (wished[r] - least[r]) * share for r in boxes}
        used = sum(width.values()) + GAP * (len(boxes) - 1)
        x = LEFT + (WIDTH - used) / 2
        y = i * BAND
        for room in boxes:
            placed[room] = (x, y, width[room])
            x += width[room] + GAP
    return placed


def draw(graph: Graph, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import FancyArrowPatch, FancyBboxPatch

    matplotlib.rcParams["svg.hashsalt"] = "seqrun-layers"  # the same file for the same graph
    matplotlib.rcParams["font.family"] = "DejaVu Sans"
    matplotlib.rcParams["svg.fonttype"] = "none"  # text stays text (searchable, small)
    placed = layout(graph)
    height = len(graph.layers) * BAND
    fig = plt.figure(figsize=(13, (height - BAND + BOX + 1.2) * 0.66))
    ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
    ax.set_xlim(0, LEFT + WIDTH + 0.3)
    ax.set_ylim(-0.9, height - BAND + BOX + 0.3)
    ax.axis("off")
    for i, (name, _) in enumerate(graph.layers):
        y = i * BAND
        ax.add_patch(FancyBboxPatch((0.1, y - 0.12), LEFT + WIDTH, BOX + 0.24,
                                    boxstyle="round,pad=0,rounding_size=0.08",
                                    facecolor="#f2f4f7" if i % 2 else "#e9edf2",
                                    edgecolor="none", zorder=0))
        ax.text(0.25, y + BOX / 2, name, fontsize=10, fontweight="bold", va="center",
                color="#37475a")
    for room, (x, y, w) in placed.items():
        ax.add_patch(FancyBboxPatch((x, y), w, BOX, boxstyle="round,pad=0,rounding_size=0.06",
                                    facecolor="white", edgecolor="#4a6076", lw=1.0, zorder=2))
        ax.text(x + 0.08, y + BOX - 0.1, room, fontsize=8.5, fontweight="bold", va="top",
                zorder=3)
        for k, line in enumerate(_label_lines(_label(graph, room), int((w - PAD) / TEXT_CHAR))):
            ax.text(x + 0.08, y + BOX - 0.34 - 0.17 * k, line, fontsize=5.6, va="top",
                    color="#445566", zorder=3)
    drawn = graph.drawn()
    # spread each box's arrows along its edge, in the order of the boxes at the other end
    outs: dict[str, list[str]] = {}
    ins: dict[str, list[str]] = {}
    for a, b in drawn:
        outs.setdefault(a, []).append(b)
        ins.setdefault(b, []).append(a)

    def centre(room: str) -> float:
        return placed[room][0] + placed[room][2] / 2

    def spot(room: str, others: list[str], other: str) -> float:
        x, _, w = placed[room]
        order = sorted(others, key=lambda r: (centre(r), r))
        return x + w * (order.index(other) + 1) / (len(order) + 1)

    for a, b in drawn:
        (xa, ya, wa), (xb, yb, wb) = placed[a], placed[b]
        up = graph.upward((a, b))
        if ya == yb:  # the same layer: side to side, over the boxes between
            left = xa < xb
            start = (xa + wa if left else xa, ya + BOX * 0.55)
            end = (xb if left else xb + wb, yb + BOX * 0.55)
            style = "arc3,rad=0" if abs(start[0] - end[0]) < GAP * 1.5 else \
                f"arc3,rad={-0.35 if left else 0.35}"
        elif up:
            start = (spot(a, outs[a], b), ya + BOX)
            end = (spot(b, ins[b], a), yb)
            style = "arc3,rad=-0.15"
        else:
            start = (spot(a, outs[a], b), ya)
            end = (spot(b, ins[b], a), yb + BOX)
            style = "arc3,rad=0"
        ax.add_patch(FancyArrowPatch(start, end, arrowstyle="-|>", mutation_scale=9,
                                     connectionstyle=style, lw=1.4 if up else 0.8,
                                     color="#c0392b" if up else "#50657a",
                                     linestyle="--" if up else "-", alpha=0.9, zorder=1.5))
    ax.text(LEFT, -0.45, "Each box is a folder of seqrun/ (or a module in it), in its layer of "
            "docs/architecture.md. An arrow: an import (at the top, in a function or for the "
            "type checker).", fontsize=6.5, color="#37475a")
    ax.text(LEFT, -0.72, "Not drawn: arrows into the base layer (every layer uses it) and "
            "arrows a longer way implies. Red, dashed: an import that runs back up. "
            "Drawn by tools/draw_layers.py.", fontsize=6.5, color="#37475a")
    if path.suffix == ".svg":
        fig.savefig(path, format="svg", metadata={"Date": None, "Creator": None,
                                                  "Title": "seqrun layers",
                                                  "Description": graph.summary()})
    else:  # a preview (.png): no graph kept, so --check never takes it for the picture
        fig.savefig(path, dpi=110)
    plt.close(fig)


def drawn_from(path: Path) -> str | None:
    """The graph summary a picture was drawn from (None: no picture, or none in it)."""
    if not path.is_file():
        return None
    found = GRAPH_RE.search(path.read_text(encoding="utf-8"))
    if found is None:
        return None
    text = found.group(1)
    for escaped, plain in (("&lt;", "<"), ("&gt;", ">"), ("&quot;", '"'), ("&amp;", "&")):
        text = text.replace(escaped, plain)
    return text


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--check", action="store_true",
                        help="exit 1 if the picture's layers are not today's")
    parser.add_argument("--out", type=Path, default=PICTURE, help="where to write the SVG")
    args = parser.parse_args(argv)
    graph = Graph()
    if args.check:
        drawn = drawn_from(args.out)
        if drawn is None or layering_of(drawn) != graph.layering():
            print(f"{args.out} is stale; run: python tools/draw_layers.py", file=sys.stderr)
            return 1
        return 0
    draw(graph, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
