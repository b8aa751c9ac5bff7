"""libyaml's parser (fast) and PyYAML's pure-Python one give the same result for every
file: the same data and node positions, or the same located errors (issue 15, item 7)."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from projecttree import ROOT
from seqrun import yamlsource
from seqrun.errors import SequenceInvalid, UserInputError
from seqrun.yamlsource import load_document
from tiers import examples

CORPUS = sorted(p for folder in ("tests/data/hostile", "tests/data/bad", "sequences", "poses",
                                 "arms") for p in (ROOT / folder).glob("*.yaml"))

pytestmark = pytest.mark.skipif(not yamlsource.USE_LIBYAML, reason="PyYAML without libyaml")


def _positions(document) -> list:
    """Every indexed key with the line/column of its key and value nodes."""
    out = []
    for keys in document._index.values():
        for key, (key_node, value_node) in keys.items():
            value = getattr(value_node, "target", value_node)
            out.append((key, key_node.start_mark.line, key_node.start_mark.column,
                        value.start_mark.line, value.start_mark.column))
    return sorted(out, key=repr)


def _outcome(path: Path, libyaml: bool, monkeypatch) -> tuple:
    monkeypatch.setattr(yamlsource, "USE_LIBYAML", libyaml)
    try:
        document = load_document(path, file="f.yaml")
    except SequenceInvalid as exc:
        return ("invalid", [str(e) for e in exc.errors])
    except UserInputError as exc:
        return ("unusable", str(exc))
    return ("ok", repr(document.data), _positions(document))


@pytest.mark.parametrize("path", CORPUS, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_both_parsers_agree_on_the_corpus(path, monkeypatch):
    assert _outcome(path, True, monkeypatch) == _outcome(path, False, monkeypatch)


def test_the_fast_parser_is_the_one_used(monkeypatch):
    used = []
    original = yamlsource._CLoader.__init__

    def spy(self, stream):
        used.append(True)
        original(self, stream)

    monkeypatch.setattr(yamlsource._CLoader, "__init__", spy)
    load_document(ROOT / "sequences" / "opsafe.yaml")
    assert used == [True]


#: Fragments that make YAML interesting: structure, quoting, anchors, tags, odd characters.
_PIECES = st.sampled_from([
    "a", "b", ":", ": ", " ", "  ", "\n", "\n  ", "- ", "-", "[", "]", "{", "}", ",", "'",
    '"', "#", "&x ", "*x", "&y ", "*y", "!!str ", "!!python/name:os.system ", "!t ", "<<: ",
    "|", ">", "?", "1", "-2.5e3", ".nan", "yes", "~", "\t", "\\", "é", "\u2028", "\x85",
    "\ufeff", "---", "...", "%YAML 1.1\n", "1:30", "0x1f", "010", "\U0001F600",
])


@settings(max_examples=examples(400), deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(st.lists(_PIECES, min_size=1, max_size=40).map("".join))
def test_both_parsers_agree_on_random_text(tmp_path, monkeypatch, text):
    path = tmp_path / "f.yaml"
    path.write_text(text, encoding="utf-8")
    assert _outcome(path, True, monkeypatch) == _outcome(path, False, monkeypatch)
