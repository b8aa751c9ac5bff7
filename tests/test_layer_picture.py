"""docs/layers.svg, the picture of the layers in docs/architecture.md, is drawn from today's
imports by tools/draw_layers.py (re-run it when the imports change)."""

from __future__ import annotations

from projecttree import ROOT, tool

draw_layers = tool("draw_layers")


def test_the_committed_picture_is_drawn_from_todays_imports(capsys):
    assert draw_layers.main(["--check"]) == 0, capsys.readouterr().err


def test_the_architecture_doc_shows_the_picture():
    assert "(layers.svg)" in (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")


def test_a_stale_picture_is_found(tmp_path, capsys):
    picture = tmp_path / "layers.svg"
    assert draw_layers.main(["--out", str(picture)]) == 0
    assert draw_layers.main(["--check", "--out", str(picture)]) == 0
    text = picture.read_text(encoding="utf-8")
    picture.write_text(text.replace("arrow schema.py -&gt; steps/\n", ""), encoding="utf-8")
    assert draw_layers.main(["--check", "--out", str(picture)]) == 1
    assert "stale" in capsys.readouterr().err


def test_the_picture_draws_every_layer_and_the_arrows_back_up():
    graph = draw_layers.Graph()
    assert [name for name, _ in graph.layers][-1] == "faces"
    assert {graph.layer[room] for room in graph.layer} == set(range(len(graph.layers)))
    drawn = graph.drawn()
    assert all(graph.layer[b] != 0 for _, b in drawn)  # nothing into the base layer drawn
    assert {e for e in graph.edges if graph.upward(e)} <= set(drawn)
    # an arrow a longer way implies is left out: the faces reach the arm through the service
    assert ("cli/", "arm/") in graph.edges and ("cli/", "arm/") not in drawn
