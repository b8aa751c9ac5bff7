"""seqrun.pattern_cache: regular expressions compiled once and kept, the same patterns.

In-process cases route ``re._compiler`` through the table only for the test (the fixture
puts back the module's own state); whole-process cases (file written, read back, the
``seqrun`` program) run in their own interpreter with the table in a temporary folder.
"""

from __future__ import annotations

import re
import warnings
from pathlib import Path
from re import _compiler

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import tiers
from startupproc import run_with_table, seqrun_program_at_exit
from seqrun import pattern_cache

NORMAL = pattern_cache._normal_compile


@pytest.fixture
def table(monkeypatch):
    """An empty table, and re._compiler recording what it passes to _sre.compile."""
    monkeypatch.setattr(_compiler, "_sre", pattern_cache.recording_sre())
    monkeypatch.setattr(pattern_cache, "_tables", {str: {}, bytes: {}})
    monkeypatch.setattr(pattern_cache, "_used", {str: set(), bytes: set()})
    monkeypatch.setattr(pattern_cache, "_added", 0)
    return pattern_cache._tables


def same_pattern(kept: re.Pattern, fresh: re.Pattern, samples) -> None:
    # Pattern equality compares the pattern, the flags and the engine's code
    assert kept == fresh
    assert type(kept.pattern) is type(fresh.pattern)
    assert (kept.flags, kept.groups, dict(kept.groupindex)) == \
           (fresh.flags, fresh.groups, dict(fresh.groupindex))
    for text in samples:
        a, b = kept.search(text), fresh.search(text)
        assert (a and (a.span(), a.groups(), a.groupdict())) == \
               (b and (b.span(), b.groups(), b.groupdict()))
        assert kept.findall(text) == fresh.findall(text)


def kept_and_fresh(pattern, flags):
    """The pattern compiled into the table, from the table, and normally."""
    first = pattern_cache.compile(pattern, flags)
    key = (pattern, flags)
    assert key in pattern_cache._tables[type(pattern)], "not kept"
    added = pattern_cache._added
    again = pattern_cache.compile(pattern, flags)
    assert pattern_cache._added == added  # from the table, not compiled again
    return first, again, NORMAL(pattern, flags)


# --- patterns drawn from the pieces of the syntax ---------------------------------------

ATOMS = ["a", "b", "Z", "0", "é", "ß", "K", "\u212a", "ſ", "İ", "\\.", "\\$", ".", "\\d",
         "\\w", "\\s", "\\D", "\\W", "\\S", "\\b", "\\B", "^", "$", "\\A", "\\Z",
         "[a-z]", "[^a-c0-9]", "[\\w.+-]", "[\\x00-\\x1f\\\\\"]", "[ά-ώ]",
         "[^\\t\\n\\r -~\\x85\\xa0-\\ud7ff\\ue000-\\ufffd\\U00010000-\\U0010ffff]",
         "\\u00e9", "\\x41", "\\n", "\\t"]


def _join(parts: list[str]) -> str:
    return "".join(parts)


patterns = st.recursive(
    st.sampled_from(ATOMS),
    lambda inner: st.one_of(
        st.lists(inner, min_size=2, max_size=4).map(_join),
        st.tuples(inner, inner).map(lambda p: f"{p[0]}|{p[1]}"),
        st.tuples(inner, st.sampled_from(["*", "+", "?", "*?", "+?", "{2}", "{1,3}",
                                          "{2,}?", "*+", "?+"])).map(lambda p: f"(?:{p[0]}){p[1]}"),
        inner.map(lambda p: f"({p})"),
        st.tuples(st.sampled_from("xyz"), inner).map(lambda p: f"(?P<{p[0]}>{p[1]})"),
        inner.map(lambda p: f"(?={p})"),
        inner.map(lambda p: f"(?!{p})"),
        inner.map(lambda p: f"(?>{p})"),
        st.sampled_from(["(?<=a)", "(?<!bc)", "(a)\\1", "(?P<w>b)(?P=w)", "(a)?(?(1)b|c)"]),
    ),
    max_leaves=8,
)
FLAG_SETS = st.sets(st.sampled_from([re.I, re.M, re.S, re.X, re.A])).map(
    lambda flags: sum(f.value for f in flags))
SAMPLES = ["", "abc", "ABC déjà vu", "a\nb\tc 0.5 $x", "K\u212a ſs İi", "aab bab ab_12",
           "\x00\x1f\"\\", "ábγδ\U0001f600"]


@settings(max_examples=tiers.examples(400), deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(pattern=patterns, flags=FLAG_SETS, as_bytes=st.booleans())
def test_a_kept_pattern_is_the_pattern_normal_compiling_makes(table, pattern, flags, as_bytes):
    samples = SAMPLES
    if as_bytes:
        try:
            pattern = pattern.encode("ascii")
        except UnicodeEncodeError:
            pattern = pattern.encode("latin-1", "replace")
        samples = [s.encode("latin-1", "replace") for s in SAMPLES]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            fresh = NORMAL(pattern, flags)
        except re.error as normal:
            # a pattern that does not compile raises the same error and is not kept
            with pytest.raises(re.error) as kept:
                pattern_cache.compile(pattern, flags)
            assert (str(kept.value), kept.value.pos) == (str(normal), normal.pos)
            assert (pattern, flags) not in table[type(pattern)]
            return
    if (pattern, flags) in table[type(pattern)] or _warns(pattern, flags):
        return  # drawn before, or kept out on purpose (test below)
    first, again, fresh = kept_and_fresh(pattern, flags)
    same_pattern(first, fresh, samples)
    same_pattern(again, fresh, samples)


def _warns(pattern, flags) -> bool:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        NORMAL(pattern, flags)
    return bool(caught)


@pytest.mark.parametrize("pattern, flags", [
    ("(?P<name>[a-zA-Z0-9_]+)=(?P<quote>[\"']?)(?P<value>.*)(?P=quote)$", 0),   # shlex-like
    ("^(?:yes|Yes|YES|no|No|NO|true|True|TRUE|false|False|FALSE|on|On|ON|off|Off|OFF)$", 0),
    ("[^\x09\x0a\x0d\x20-\x7e\x85\xa0-\ud7ff\ue000-\ufffd\U00010000-\U0010ffff]", 0),  # yaml
    ("\n  (?P<sign>[-+ ]?)  # a verbose pattern\n  (?P<digits>\\d+)\n", re.X.value),
    ("straße|STRASSE", re.I.value),
    ("straße|STRASSE", (re.I | re.A).value),
    (b"=([a-fA-F0-9]{2})", 0),
    (b"[\x80-\xff]+", re.I.value),
    (b"^\\w+$", (re.L | re.M).value),
])
def test_patterns_of_each_kind_from_the_table(table, pattern, flags):
    first, again, fresh = kept_and_fresh(pattern, flags)
    samples = [b"abc", b"=4F=zz", b"\xe9t\xe9", b"name\nx"] if isinstance(pattern, bytes) \
        else ["yes", "no", "x\x07y", "\u00e9", "-12", "Strasse", "STRAßE", "ſtraße"]
    same_pattern(again, fresh, samples)


def test_a_pattern_whose_compiling_warns_warns_every_time_and_is_not_kept(table, monkeypatch):
    warn = warnings.warn
    with pytest.warns(FutureWarning, match="nested set") as normal:
        re.purge()
        re.compile("[[a-z]--x]")
    monkeypatch.setattr(_compiler, "compile", pattern_cache.compile)
    for _ in range(2):
        re.purge()
        with pytest.warns(FutureWarning, match="nested set") as caught:
            re.compile("[[a-z]--x]")
        # it still points at the line that called re.compile
        assert (caught[0].filename, caught[0].lineno) == (__file__, normal[0].lineno + 5)
    assert ("[[a-z]--x]", 0) not in table[str]
    assert warnings.warn is warn


def test_the_debug_flag_and_parsed_patterns_compile_normally(table, capsys):
    pattern_cache.compile("a+", re.DEBUG.value)
    assert "MAX_REPEAT" in capsys.readouterr().out
    parsed = re._parser.parse("b+", 0)
    assert pattern_cache.compile(parsed, 0).match("bb")
    assert not table[str]


def test_a_damaged_entry_compiles_normally_and_is_replaced(table):
    kept_and_fresh("x(y)z", 0)
    final_flags, code, *rest = table[str][("x(y)z", 0)]
    table[str][("x(y)z", 0)] = (final_flags, [999_999, 1, 2], *rest)
    assert pattern_cache.compile("x(y)z", 0) == NORMAL("x(y)z", 0)
    assert table[str][("x(y)z", 0)][1] == code


def test_a_str_and_a_bytes_pattern_alike_are_kept_apart(table):
    assert hash("ab+") == hash(b"ab+")
    with warnings.catch_warnings():
        warnings.simplefilter("error", BytesWarning)   # what python -b would say
        _, text, _ = kept_and_fresh("ab+", 0)
        _, data, _ = kept_and_fresh(b"ab+", 0)
    assert text.pattern == "ab+" and data.pattern == b"ab+"


# --- whole processes ---------------------------------------------------------------------

SCRIPT = """\
import json, re, sys
from pathlib import Path
from seqrun import pattern_cache
table = Path(sys.argv[1])
if sys.argv[2] == "install":
    pattern_cache.table_path = lambda: table
    pattern_cache.install()
import textwrap, json as _json, yaml.resolver, yaml.reader
patterns = [re.compile(p, f) for p, f in (
    ("(?P<k>\\\\w+)=(?P<v>[^;]*)", 0), ("ab+c", re.I), (b"[\\\\x80-\\\\xff]", 0))]
patterns += [yaml.reader.Reader.NON_PRINTABLE, textwrap.TextWrapper.wordsep_re]
pattern_cache.save()
print(json.dumps({
    "added": pattern_cache._added,
    "patterns": [[repr(p), p.flags, p.groups, dict(p.groupindex)] for p in patterns],
    "matches": [repr(p.findall(s)) for p in patterns
                for s in (("k=v;x=\\u00e9", "ABBC", "\\u2028\\x07") if isinstance(p.pattern, str)
                          else (b"\\xe9t\\xe9",))],
}))
"""


def run(table: Path, mode: str, *, write: bool = True) -> dict:
    return run_with_table(SCRIPT, table, mode, write=write)


def test_a_second_process_compiles_nothing_and_makes_the_same_patterns(tmp_path):
    table = tmp_path / "compiled-patterns.marshal"
    plain = run(table, "plain")
    first = run(table, "install")
    assert first["added"] >= 10 and table.is_file()  # textwrap's, json's, yaml's, the three
    second = run(table, "install")
    assert second["added"] == 0
    for result in (first, second):
        assert {k: v for k, v in result.items() if k != "added"} == \
               {k: v for k, v in plain.items() if k != "added"}


def test_no_table_is_written_when_bytecode_writing_is_off(tmp_path):
    table = tmp_path / "compiled-patterns.marshal"
    assert run(table, "install", write=False)["added"] >= 10
    assert not table.exists()


def test_a_damaged_table_or_one_of_another_python_is_ignored_and_replaced(tmp_path):
    import marshal

    table = tmp_path / "compiled-patterns.marshal"
    table.write_bytes(b"\x00not a table")
    assert run(table, "install")["added"] >= 10
    assert run(table, "install")["added"] == 0
    header, tables = marshal.loads(table.read_bytes())
    assert header == pattern_cache.header()
    other = (header[0], header[1] + " (another build)", *header[2:])
    table.write_bytes(marshal.dumps((other, tables)))
    assert run(table, "install")["added"] >= 10


def test_the_seqrun_program_installs_it():
    words = seqrun_program_at_exit(
        "import atexit, sys, re\n"
        "atexit.register(lambda: print(re._compiler.compile.__module__, file=sys.stderr))")
    assert words[-1] == "seqrun.pattern_cache"
