"""yamlsource: safe YAML -> pydantic with file:line:col errors."""

from __future__ import annotations

import math
import re
from typing import Annotated

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pydantic import BaseModel, ConfigDict, Field

from projecttree import ARM_FILE
from seqrun import yamlsource
from seqrun.errors import SequenceInvalid, UserInputError
from seqrun.yamlsource import FriendlyModel, load_document, load_model


def write(tmp_path, text: str | bytes, name: str = "f.yaml"):
    path = tmp_path / name
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text, encoding="utf-8")
    return path


def errors_of(path, model=None) -> list[tuple[int, int, str]]:
    with pytest.raises(SequenceInvalid) as info:
        if model is None:
            load_document(path)
        else:
            load_model(path, model)
    for error in info.value.errors:
        assert error.file == yamlsource.display_path(path)
    return [(e.line, e.column, e.message) for e in info.value.errors]


def only_error(path, model=None) -> tuple[int, int, str]:
    errors = errors_of(path, model)
    assert len(errors) == 1, errors
    return errors[0]


# ----------------------------------------------------------------------------- YAML 1.2 core
def test_yaml_1_1_surprises_are_switched_off(tmp_path):
    doc = load_document(write(tmp_path, """\
a: yes
b: no
c: on
d: 1:30
e: 010
f: 2024-01-01
g: 1e3
h: 0x1f
i: True
j: ~
k: .inf
l: nan
m: '12'
"""))
    assert doc.data == {"a": "yes", "b": "no", "c": "on", "d": "1:30", "e": 10,
                        "f": "2024-01-01", "g": 1000.0, "h": 31, "i": True, "j": None,
                        "k": math.inf, "l": "nan", "m": "12"}


def test_keys_that_yaml_1_1_turns_into_booleans_stay_text(tmp_path):
    doc = load_document(write(tmp_path, "on: 1\nno: 2\n"))
    assert doc.data == {"on": 1, "no": 2}


def test_explicit_core_tags_are_allowed_and_checked(tmp_path):
    assert load_document(write(tmp_path, "a: !!str 12\nb: !!float 1\n")).data == {
        "a": "12", "b": 1.0}
    assert only_error(write(tmp_path, "a: !!int abc\n")) == (1, 4, "'abc' is not a valid !!int")


# ----------------------------------------------------------------------------- refusals
@pytest.mark.parametrize("text, line, col, words", [
    ("a: 1\nb: !!python/object/apply:os.system ['ls']\n", 2, 4,
     ["'!!python/object/apply:os.system'", "not allowed"]),
    ("a: !!python/name:os.system ''\n", 1, 4, ["!!python/name:os.system", "not allowed"]),
    ("a: !custom 1\n", 1, 4, ["'!custom'", "not allowed"]),
    ("a: !!binary aGk=\n", 1, 4, ["!!binary"]),
    ("a: !!set {x: null}\n", 1, 4, ["!!set"]),
    ("a: !!timestamp 2024-01-01\n", 1, 4, ["!!timestamp"]),
])
def test_unsafe_and_unknown_tags_are_located_errors(tmp_path, text, line, col, words):
    got_line, got_col, message = only_error(write(tmp_path, text))
    assert (got_line, got_col) == (line, col)
    for word in words:
        assert word in message


def test_duplicate_key_is_located_at_the_second_key(tmp_path):
    path = write(tmp_path, "a: 1\nb:\n  c: 1\n  d: 2\n  c: 3\n")
    assert only_error(path) == (5, 3, "duplicate key 'c' (first given at line 3)")


def test_every_duplicate_key_and_tag_is_reported_at_once(tmp_path):
    path = write(tmp_path, "a: 1\na: 2\nb: !foo x\nc: [1, !!set {}]\n")
    assert [(line, col) for line, col, _ in errors_of(path)] == [(2, 1), (3, 4), (4, 8)]


def test_merge_keys_are_refused(tmp_path):
    path = write(tmp_path, "x: &a {b: 1}\ny:\n  <<: *a\n")
    line, col, message = only_error(path)
    assert (line, col) == (3, 3) and "merge keys" in message


def test_aliases_within_limits_are_expanded(tmp_path):
    doc = load_document(write(tmp_path, "a: &v [1, 2]\nb: *v\n"))
    assert doc.data == {"a": [1, 2], "b": [1, 2]}


def test_billion_laughs_is_refused_at_the_alias(tmp_path):
    lines = ['a: &a ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
    for prev, name in zip("abcdefgh", "bcdefghi"):
        lines.append(f"{name}: &{name} [" + ", ".join([f"*{prev}"] * 10) + "]")
    line, col, message = only_error(write(tmp_path, "\n".join(lines) + "\n"))
    assert line == 5 and "alias bomb" in message and str(yamlsource.MAX_EXPANDED_NODES) in message
    assert lines[line - 1][col - 1] == "*"


def test_too_many_alias_uses(tmp_path, monkeypatch):
    monkeypatch.setattr(yamlsource, "MAX_ALIAS_USES", 3)
    line, col, message = only_error(write(tmp_path, "a: &x 1\nb: [*x, *x, *x, *x]\n"))
    assert (line, col) == (2, 17) and "too many aliases" in message


def test_recursive_alias(tmp_path):
    line, col, message = only_error(write(tmp_path, "a: &x [1, *x]\n"))
    assert (line, col) == (1, 11) and "recursive alias '*x'" in message


def test_nesting_depth_limit(tmp_path):
    depth = yamlsource.MAX_DEPTH + 5
    line, col, message = only_error(write(tmp_path, "a: " + "[" * depth + "]" * depth + "\n"))
    assert line == 1 and col == 4 + yamlsource.MAX_DEPTH - 1 and "nested too deeply" in message


def test_deep_nesting_never_hits_python_recursion(tmp_path):
    text = "a: " + "[" * 5000 + "]" * 5000 + "\n"
    assert "nested too deeply" in only_error(write(tmp_path, text))[2]


def test_size_limit(tmp_path, monkeypatch):
    monkeypatch.setattr(yamlsource, "MAX_FILE_BYTES", 100)
    line, col, message = only_error(write(tmp_path, "a: " + "x" * 200 + "\n"))
    assert (line, col) == (1, 1) and "too large" in message


def test_multi_document_files_are_refused(tmp_path):
    line, col, message = only_error(write(tmp_path, "a: 1\n---\nb: 2\n"))
    assert (line, col) == (2, 1) and "only one YAML document" in message


@pytest.mark.parametrize("content, message", [
    ("", "the file is empty"),
    ("   \n\n", "the file is empty"),
    ("# just a comment\n", "the file has no content (only comments)"),
])
def test_empty_files(tmp_path, content, message):
    assert only_error(write(tmp_path, content)) == (1, 1, message)


def test_non_utf8_bytes_are_located(tmp_path):
    line, col, message = only_error(write(tmp_path, b"a: 1\nb: caf\xe9\n"))
    assert (line, col) == (2, 7) and "not UTF-8" in message and "0xe9" in message


def test_column_of_bad_byte_counts_characters_not_bytes(tmp_path):
    line, col, _ = only_error(write(tmp_path, b"a: \xc3\xa9\xff\n"))  # 'a: é' then 0xff
    assert (line, col) == (1, 5)


def test_utf8_bom_is_accepted(tmp_path):
    assert load_document(write(tmp_path, b"\xef\xbb\xbfa: 1\n")).data == {"a": 1}


def test_control_characters_are_located(tmp_path):
    line, col, message = only_error(write(tmp_path, "a: 1\nb: x\x01\n"))
    assert (line, col) == (2, 5) and "U+0001" in message


@pytest.mark.parametrize("text, line, col, words", [
    ("a: [1, 2\nb: 3\n", 2, 2, ["expected ',' or ']'", "line 1"]),
    ("a:\n  b: 1\n c: 2\n", 3, 2, ["indentation"]),
    ("a: b: c\n", 1, 5, ["unexpected ':'"]),
    ('a: "open\n', 2, 1, ["closing quote", "line 1"]),
    ("a:\n\tb: 1\n", 2, 1, ["tabs"]),
    ("a: *nothing\n", 1, 4, ["undefined alias"]),
])
def test_syntax_errors_are_located_from_the_problem_mark(tmp_path, text, line, col, words):
    got_line, got_col, message = only_error(write(tmp_path, text))
    assert (got_line, got_col) == (line, col), message
    for word in words:
        assert word in message


def test_unreadable_files_are_user_input_errors(tmp_path):
    with pytest.raises(UserInputError, match="no such file"):
        load_document(tmp_path / "missing.yaml")
    with pytest.raises(UserInputError, match="directory"):
        load_document(tmp_path)


# ----------------------------------------------------------------------------- models
class Inner(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True)
    speed: Annotated[float, Field(gt=0, allow_inf_nan=False)]
    on: bool = False


class Outer(FriendlyModel):
    model_config = ConfigDict(extra="forbid", strict=True)
    yaml_name = "the file"
    name: str
    items: list[Inner] = Field(default_factory=list)
    table: dict[str, float] = Field(default_factory=dict)


def test_errors_point_at_the_value_and_read_well(tmp_path):
    path = write(tmp_path, """\
name: 12
items:
  - speed: -1
  - speed: .nan
    on: yes
  - {speed: 1:30}
table: {a: 1, 3: 2}
""")
    assert errors_of(path, Outer) == [
        (1, 7, "expected text, got 12 (put it in quotes if you mean text)"),
        (3, 12, "must be greater than 0, got -1"),
        (4, 12, "expected a finite number, got .nan (NaN and infinity are not allowed)"),
        (5, 9, ("expected true or false, got 'yes' (seqrun reads YAML 1.2: yes/no/on/off are "
               "words, not booleans)")),
        (6, 13, ("expected a number, got '1:30' (seqrun reads YAML 1.2: '1:30' is text, not the "
                "base-60 number 90; write the value in degrees or seconds)")),
        (7, 15, "expected text, got 3 (put it in quotes if you mean text)"),
    ]


def test_missing_key_points_at_the_parent_mapping(tmp_path):
    path = write(tmp_path, "name: x\nitems:\n  - on: true\n")
    assert errors_of(path, Outer) == [(3, 5, "missing required key 'speed' in items item 1")]


def test_unknown_key_points_at_the_key_and_suggests(tmp_path):
    path = write(tmp_path, "name: x\nnmae: y\nitems:\n  - {speed: 1, sped: 2}\n")
    assert errors_of(path, Outer) == [
        (2, 1, ("unknown key 'nmae' in the file (did you mean 'name'? allowed: name, items, "
               "table)")),
        (4, 16, "unknown key 'sped' in items item 1"),
    ]


def test_document_that_is_not_a_mapping(tmp_path):
    assert errors_of(write(tmp_path, "- a\n- b\n"), Outer) == [
        (1, 1, "expected a mapping (key: value), got a list")]


def test_errors_inside_an_alias_point_at_the_anchored_value(tmp_path):
    path = write(tmp_path, "name: x\ncommon: &c {speed: -2}\n")
    # 'common' is unknown; the bad value itself is where the anchor defines it
    errors = errors_of(path, Outer)
    assert errors[0][:2] == (2, 1)


def test_load_model_returns_the_model(tmp_path):
    outer = load_model(write(tmp_path, "name: x\nitems: [{speed: 2}]\n"), Outer)
    assert outer.items[0].speed == 2.0


def test_arm_file_goes_through_yamlsource():
    from seqrun.arm.description import load_arm

    arm = load_arm(ARM_FILE)
    assert arm.joint("j3").locked == 0.0


def test_arm_file_errors_are_located(tmp_path):
    from seqrun.arm.description import load_arm

    text = ARM_FILE.read_text(encoding="utf-8")
    text = text.replace("cycle_hz: 100", "cycle_hz: fast")
    path = write(tmp_path, text, "arm.yaml")
    with pytest.raises(SequenceInvalid) as info:
        load_arm(path)
    [error] = info.value.errors
    line = text.splitlines().index(next(l for l in text.splitlines() if "cycle_hz" in l)) + 1
    assert (error.line, error.column) == (line, 13)
    assert error.message == "expected a number, got 'fast'"


_PYTHON_ONLY_ALPHABET = st.sampled_from(
    list("ab #|>-+09%!?[]{},: \n\r\t") + ["\ufeff", "\x85", "\x7f", "\x00", "\ud800", "\ue000",
                                           "\ufffe", "\uffff", "\U0001F600", "\xa0", "\x1f",
                                           "\ufefe", "\uff00", "\ufffd"])


@settings(max_examples=2000, deadline=None)
@given(st.text(_PYTHON_ONLY_ALPHABET, max_size=16) | st.text(max_size=16))
def test_python_only_check_is_the_one_pattern(text):
    """_python_only searches the parts of _PYTHON_ONLY one by one (faster); same answer."""
    question = text.rfind("?")
    brackets = [i for i in (text.find("["), text.find("{")) if i >= 0]
    expected = bool(re.search(yamlsource._PYTHON_ONLY, text, re.MULTILINE)) or (
        question >= 0 and bool(brackets) and min(brackets) < question)
    assert yamlsource._python_only(text) == expected
