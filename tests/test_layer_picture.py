"""docs/layers.svg, the picture of the layers in docs/architecture.md, is drawn from the
imports by tools/draw_layers.py; it must show today's layers (re-run it when they change)."""

from __future__ import annotations

from projecttree import ROOT, tool

draw_layers = tool("draw_layers")


def test_the_committed_picture_shows_todays_layers(capsys):
    assert draw_layers.main(["--check"]) == 0, capsys.readouterr().err


def test_the_architecture_doc_shows_the_picture():
    assert "(layers.svg)" in (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")


def test_a_stale_picture_is_found(tmp_path, capsys):
    picture = tmp_path / "layers.svg"
    assert draw_layers.main(["--out", str(picture)]) == 0
    assert draw_layers.main(["--check", "--out", str(picture)]) == 0
    text = picture.read_text(encoding="utf-8")
    # a box in another layer: stale
    moved = text.replace("layer wire: powercube/ sim/", "layer wire: powercube/")
    assert moved != text
    picture.write_text(moved, encoding="utf-8")
    assert draw_layers.main(["--check", "--out", str(picture)]) == 1
    assert "stale" in capsys.readouterr().err


def test_an_arrow_back_up_makes_the_picture_stale(tmp_path, capsys):
    picture = tmp_path / "layers.svg"
    assert draw_layers.main(["--out", str(picture)]) == 0
    text = picture.read_text(encoding="utf-8")
    backup = text.replace("arrow schema.py -&gt; steps/\n",
                          "arrow schema.py -&gt; steps/\narrow arm/ -&gt; cli/ (back up)\n")
    assert backup != text
    picture.write_text(backup, encoding="utf-8")
    assert draw_layers.main(["--check", "--out", str(picture)]) == 1


def test_a_new_module_or_a_downward_import_leaves_the_picture_current(tmp_path):
    picture = tmp_path / "layers.svg"
    assert draw_layers.main(["--out", str(picture)]) == 0
    text = picture.read_text(encoding="utf-8")
    changed = text.replace("arrow schema.py -&gt; steps/\n", "")
    assert changed != text
    picture.write_text(changed, encoding="utf-8")
    assert draw_layers.main(["--check", "--out", str(picture)]) == 0


def test_the_picture_draws_every_layer_and_the_arrows_back_up():
    graph = draw_layers.Graph()
    assert [name for name, _ in graph.layers][-1] == "faces"
    assert {graph.layer[room] for room in graph.layer} == set(range(len(graph.layers)))
    drawn = graph.drawn()
    assert all(graph.layer[b] != 0 for _, b in drawn)  # nothing into the base layer drawn
    assert {e for e in graph.edges if graph.upward(e)} <= set(drawn)
    # an arrow a longer way implies is left out: the faces reach the arm through the service
    assert ("cli/", "arm/") in graph.edges and ("cli/", "arm/") not in drawn
