"""Hostile and random input through the command line, as the operator types it.

Every sequence file here goes through BOTH ``seqrun validate FILE`` and ``seqrun run FILE
--virtual-time --yes --plain --no-report --log-dir DIR`` (typer's CliRunner, in-process, so
the simulator can be watched; report.html, drawn after the run and never into its outcome,
has its own tests in test_report.py). The contract:

- never a traceback (``result.exception`` is a ``SystemExit`` or nothing);
- a file that cannot be used at all: one ``error:`` line, exit 2;
- an invalid file: ``file:line:col: message`` lines, exit 1 — and ``seqrun run`` opens no
  bus, sends no frame and creates no run folder (checked by wrapping ``SimBus.__init__`` and
  ``SimBus.send``; :func:`test_the_spy_sees_a_real_run` shows the same spy sees a run).
  That includes files that load but are invalid from the start pose (Park, not started up:
  a move before Home, a target out of limits): ``seqrun run`` validates statically too
  before it opens the bus (and again from the measured state before the first motion);
- a valid file: ``validate`` exit 0 (or 1 when its dry run fails), ``run`` exit 0, or 3 for
  a fault the simulator raised (clean Halt, never a traceback);
- no code from the file is ever executed: the payloads create marker files when loaded
  with ``yaml.unsafe_load`` (:func:`test_the_payloads_are_live`), and never here.

Part (b) at the end: bad command-line options are one ``error:`` line and exit 2.
"""

from __future__ import annotations

import contextlib
import itertools
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from unittest import mock

import pytest
import yaml
from hypothesis import HealthCheck, event, example, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

import seqrun.cli  # noqa: F401  (runs seqrun.cli._load_commands: every command registered)
from projecttree import ROOT, make_project
from runfolder import RunFolder
from seqrun.arm.description import load_arm
from seqrun.cli.app import app
from seqrun.errors import SequenceInvalid, UserInputError
from seqrun.powercube.codec import decode_request
from seqrun.sequence.loader import load_sequence
from seqrun.sim.bus import SimBus
from seqrun.sequence.validation import validate_sequence

BAD = ROOT / "tests" / "data" / "bad"
HOSTILE = ROOT / "tests" / "data" / "hostile"
LOCATED = re.compile(r"^(?P<file>[^:\n]+):(?P<line>[1-9][0-9]*):(?P<col>[1-9][0-9]*): "
                     r"(?P<msg>\S.*)$")

runner = CliRunner()
_run_dirs = itertools.count(1)


# ----------------------------------------------------------------------------- the spy
@dataclass
class BusSpy:
    """Every SimBus opened and every frame seqrun sent on one (the simulator's modules
    answer through the wire, not through ``SimBus.send``)."""

    buses: int = 0
    frames: list = field(default_factory=list)

    @contextlib.contextmanager
    def watching(self):
        init, send = SimBus.__init__, SimBus.send
        spy = self

        def counting_init(bus, *args, **kwargs):
            spy.buses += 1
            init(bus, *args, **kwargs)

        def recording_send(bus, msg, timeout=None):
            spy.frames.append(msg)
            return send(bus, msg, timeout)

        with mock.patch.object(SimBus, "__init__", counting_init), \
                mock.patch.object(SimBus, "send", recording_send):
            yield self

    def requests(self) -> list:
        return [decode_request(m.arbitration_id, bytes(m.data)) for m in self.frames]


@dataclass
class Invocation:
    args: list[str]
    exit_code: int
    stdout: str
    stderr: str
    exception: BaseException | None
    spy: BusSpy

    def describe(self) -> str:
        return (f"seqrun {' '.join(a[:80] for a in self.args)} -> exit {self.exit_code}\n"
                f"stdout: {self.stdout[-2000:]}\nstderr: {self.stderr[-2000:]}\n"
                f"exception: {self.exception!r}")


def invoke(*args, cwd: Path) -> Invocation:
    """One in-process command with the simulator watched, in ``cwd``."""
    spy = BusSpy()
    argv = [str(a) for a in args]
    with contextlib.chdir(cwd), spy.watching():
        result = runner.invoke(app, argv)
    return Invocation(argv, result.exit_code, result.stdout, result.stderr, result.exception,
                      spy)


def assert_no_crash(r: Invocation) -> None:
    assert r.exception is None or isinstance(r.exception, SystemExit), r.describe()
    assert "Traceback" not in r.stdout + r.stderr, r.describe()


def assert_one_error_line(r: Invocation) -> None:
    assert_no_crash(r)
    assert r.exit_code == 2, r.describe()
    lines = r.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and lines[0][7:].strip(), (
        r.describe())


# ----------------------------------------------------------------------------- the oracle
def verdict(path: Path) -> str:
    """What the library says, independently of the CLI: unusable | invalid (does not load)
    | refused_at_start (loads, but not valid from Park before the start-up) | valid."""
    try:
        loaded = load_sequence(path)
    except UserInputError:
        return "unusable"
    except SequenceInvalid:
        return "invalid"
    try:
        arm = load_arm(loaded.arm_path)
    except (SequenceInvalid, UserInputError, OSError):
        return "invalid"
    return "valid" if validate_sequence(loaded, arm).valid else "refused_at_start"


# ----------------------------------------------------------------------------- the contract
def check_file(path: Path, *, sandbox: Path, logs: Path, markers: tuple[Path, ...] = ()
               ) -> tuple[str, Invocation, Invocation]:
    """validate and run ``path``; assert the contract of the module docstring."""
    expected = verdict(path)
    folder = logs / f"run-{next(_run_dirs)}"
    v = invoke("validate", path, cwd=sandbox)
    r = invoke("run", path, "--virtual-time", "--yes", "--plain", "--no-report",
               "--log-dir", folder, cwd=sandbox)
    assert_no_crash(v)
    assert_no_crash(r)

    if expected == "unusable":
        assert_one_error_line(v)
        assert_one_error_line(r)
        assert v.stdout == ""
    elif expected in ("invalid", "refused_at_start"):
        assert v.exit_code == 1, v.describe()
        assert v.stderr == "", v.describe()
        *found, summary = v.stdout.splitlines()
        assert ": invalid (" in summary, v.describe()
        errors = [line for line in found if ": note: " not in line]
        assert errors, v.describe()
        for line in found:
            assert LOCATED.match(line), f"not file:line:col: {line!r}\n{v.describe()}"
        count = int(re.search(r": invalid \(([0-9]+) error", summary).group(1))
        assert count == len(errors), v.describe()
        assert v.spy.buses == 0 and not v.spy.frames, v.describe()   # no dry run either
        assert r.exit_code == 1, r.describe()
        # seqrun run: the same errors, each a `file:line:col: message` line (prefixed with
        # `error: ` when the file does not even load), then perhaps a summary ...
        lines = [line.removeprefix("error: ") for line in r.stderr.splitlines()]
        if lines and lines[-1].endswith("nothing was sent"):
            lines.pop()
        assert lines == errors, r.describe()
        # ... and nothing reached a bus: none opened, no frame, no trace; the run folder
        # holds only the short record of the refusal.
        assert r.spy.buses == 0, r.describe()
        assert r.spy.frames == [], r.describe()
        assert RunFolder(folder).trace_path() is None, r.describe()
        refused = RunFolder(folder).report()
        assert refused["status"] == "refused" and refused["exit_code"] == 1, r.describe()
    elif expected == "valid":
        assert v.exit_code in (0, 1), v.describe()
        assert ": valid (" in v.stdout, v.describe()            # the static verdict
        assert r.exit_code in (0, 3), r.describe()              # passed, or a clean fault
        report = RunFolder(folder).report()
        assert report["exit_code"] == r.exit_code
        assert report["status"] == ("passed" if r.exit_code == 0 else "failed")
        if r.exit_code == 3:
            assert report["fault"] and report["fault"]["halt_sent"] is True, report
    # Nothing from the file ran: no marker anywhere, the sandbox (cwd) left empty.
    for marker in markers:
        assert not marker.exists(), f"{marker} was created: code from {path} ran"
    assert list(sandbox.iterdir()) == [], list(sandbox.iterdir())
    return expected, v, r


@pytest.fixture
def places(tmp_path):
    sandbox, logs = tmp_path / "cwd", tmp_path / "logs"
    sandbox.mkdir()
    logs.mkdir()
    return sandbox, logs


def make_sequences(root: Path) -> Path:
    """The sequences/ folder of a project tree at ``root``, for generated files."""
    return make_project(root, campaign=False) / "sequences"


# ----------------------------------------------------------------------------- controls
def test_the_spy_sees_a_real_run(places):
    """The zero-frame assertions mean something: the same spy sees a valid file's run."""
    sandbox, logs = places
    expected, v, r = check_file(HOSTILE / "bom_valid.yaml", sandbox=sandbox, logs=logs)
    assert expected == "valid" and v.exit_code == 0 and r.exit_code == 0, r.describe()
    assert r.spy.buses == 1 and len(r.spy.frames) > 20
    kinds = {type(q).__name__ for q in r.spy.requests()}
    assert {"GetParam", "BroadcastRequest", "SetParam"} <= kinds, kinds  # reset/home, limits


def test_the_payloads_are_live(tmp_path):
    """The python-tag files really run their command under an unsafe loader, so the marker
    checks below would catch a loader that executed them."""
    names = {"python_apply_os_system.yaml": "pwned-apply",
             "python_apply_in_name.yaml": "pwned-name",
             "python_object_new.yaml": "pwned-new",
             "tag_directive.yaml": "pwned-directive",
             "verbatim_tag.yaml": "pwned-verbatim"}
    with contextlib.chdir(tmp_path):
        for name in names:
            yaml.unsafe_load((HOSTILE / name).read_text(encoding="utf-8"))
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(names.values())


# ----------------------------------------------------------------------------- the corpus
#: tests/data/hostile: file -> (verdict, words of the first message; None for valid files).
HOSTILE_FILES = {
    "python_apply_os_system.yaml": ("invalid", "tag '!!python/object/apply:os.system' is not"),
    "python_apply_in_name.yaml": ("invalid", "tag '!!python/object/apply:os.system' is not"),
    "python_object_new.yaml": ("invalid", "tag '!!python/object/new:tuple' is not allowed"),
    "python_name.yaml": ("invalid", "tag '!!python/name:os.system' is not allowed"),
    "python_module.yaml": ("invalid", "tag '!!python/module:os' is not allowed"),
    "tag_directive.yaml": ("invalid", "tag '!!python/object/apply:os.system' is not allowed"),
    "verbatim_tag.yaml": ("invalid", "tag '!!python/object/apply:os.system' is not allowed"),
    "custom_include_tag.yaml": ("invalid", "tag '!include' is not allowed"),
    "huge_numbers.yaml": ("invalid", "expected a finite number, got .inf"),
    "nan_inf_everywhere.yaml": ("invalid", "expected a finite number"),
    "tiny_numbers.yaml": ("invalid", "must be at least 0.01, got 0"),
    "unknown_keys.yaml": ("invalid", "unknown key 'arm_file'"),
    "bidi_key.yaml": ("invalid", "unknown key 'st\u202espe'"),
    "utf16.yaml": ("invalid", "not UTF-8 text"),
    "overlong_utf8.yaml": ("invalid", "not UTF-8 text: byte 0xc0"),
    "surrogate_utf8.yaml": ("invalid", "not UTF-8 text: byte 0xed"),
    "truncated_utf8.yaml": ("invalid", "not UTF-8 text"),
    "nul_byte.yaml": ("invalid", "U+0000 is not allowed"),
    "escaped_surrogate.yaml": ("invalid", "valid string"),
    "line_separator.yaml": ("invalid", "duplicate key 'steps'"),
    "merge_key.yaml": ("invalid", "merge keys"),
    "recursive_alias.yaml": ("invalid", "recursive alias '*s'"),
    "undefined_alias.yaml": ("invalid", "undefined alias 'nowhere'"),
    "multi_document.yaml": ("invalid", "only one YAML document"),
    "yaml_directive.yaml": ("invalid", "'1:30' is text"),
    "include_absolute.yaml": ("invalid", "is outside the sequences folder"),
    "include_parent.yaml": ("invalid", "is outside the sequences folder"),
    "include_self.yaml": ("invalid", "include loop: include_self.yaml -> include_self.yaml"),
    "not_a_mapping.yaml": ("invalid", "expected a mapping"),
    "whitespace_only.yaml": ("invalid", "the file is empty"),
    "comment_only.yaml": ("invalid", "no content"),
    "null_document.yaml": ("invalid", "expected a mapping"),
    "bom_valid.yaml": ("valid", None),
    "bom_inside.yaml": ("valid", None),
    "odd_unicode_valid.yaml": ("valid", None),
    "alias_steps.yaml": ("valid", None),
}


def test_every_hostile_file_is_listed():
    assert sorted(p.name for p in HOSTILE.glob("*.yaml")) == sorted(HOSTILE_FILES)


@pytest.mark.parametrize("name", sorted(HOSTILE_FILES))
def test_hostile_file(name, places):
    sandbox, logs = places
    want, words = HOSTILE_FILES[name]
    markers = tuple(sandbox / m for m in ("pwned-apply", "pwned-name", "pwned-new",
                                          "pwned-directive", "pwned-verbatim"))
    expected, v, r = check_file(HOSTILE / name, sandbox=sandbox, logs=logs, markers=markers)
    assert expected == want, v.describe()
    if words is None:
        assert v.exit_code == 0 and r.exit_code == 0, r.describe()
    else:
        assert words in v.stdout.splitlines()[0], v.describe()


@pytest.mark.parametrize("path", sorted(BAD.glob("*.yaml")), ids=lambda p: p.name)
def test_bad_file(path, places):
    sandbox, logs = places
    expected, _, _ = check_file(path, sandbox=sandbox, logs=logs)
    assert expected in ("invalid", "refused_at_start")


def _generated(seqs: Path, tmp: Path) -> dict[str, tuple[Path, str, str]]:
    """Files too big to commit, or naming paths of this machine: name -> (path, verdict,
    words in the first message)."""
    head = "name: Generated\ndescription: made at test time\nsteps:\n"
    startup = "  - reset\n  - home\n  - set_limits\n"
    out: dict[str, tuple[Path, str, str]] = {}

    def put(name: str, content: str | bytes, want: str, words: str) -> None:
        path = seqs / f"{name}.yaml"
        if isinstance(content, bytes):
            path.write_bytes(content)
        else:
            path.write_text(content, encoding="utf-8")
        out[name] = (path, want, words)

    put("five_megabytes", head + startup + "# padding padding padding\n" * 200_000,
        "invalid", "too large")
    put("five_megabytes_one_line", "name: " + "x" * 5_000_000 + "\n", "invalid", "too large")
    put("ten_to_the_1000", head + startup + "  - move: {joints: {j1: 1" + "0" * 1000 + "}}\n",
        "invalid", "a whole number of 1001 characters is too long")
    put("digits_100000", head + startup + "  - wait: " + "9" * 100_000 + "\n",
        "invalid", "a whole number of 100000 characters is too long")
    put("hex_5000", "name: 0x" + "f" * 5000 + "\ndescription: d\nsteps: [reset]\n",
        "invalid", "a whole number of 5002 characters is too long")
    put("float_5000_digits", head + startup + "  - move: {joints: {j1: 0." + "3" * 5000
        + "}}\n", "valid", "")
    put("e400", head + startup + "  - move: {joints: {j1: 1e400}}\n",
        "invalid", "expected a finite number, got .inf")
    put("nested_200_flow", head + "  - confirm: " + "[" * 200 + "]" * 200 + "\n",
        "invalid", "nested too deeply")
    put("nested_200_block", "name: X\ndescription: d\nsteps:\n"
        + "".join("  " * (i + 1) + "-\n" for i in range(200)), "invalid", "nested too deeply")
    put("nested_200_mappings", "name: X\ndescription: d\nsteps:\n  - move:\n"
        + "".join("  " * (i + 3) + f"k{i}:\n" for i in range(200)),
        "invalid", "nested too deeply")
    anchors = ["a: &a [" + ", ".join(['"' + "lol" * 50 + '"'] * 10) + "]"]
    anchors += [f"{n}: &{n} [" + ", ".join([f"*{p}"] * 10) + "]"
                for p, n in zip("abcdefghijkl", "bcdefghijklm")]
    put("billion_laughs_deeper", "name: X\ndescription: d\n" + "\n".join(anchors)
        + "\nsteps: *m\n", "invalid", "alias bomb")
    put("alias_flood", "name: X\ndescription: d\nx: &x " + "y" * 100_000 + "\nsteps:\n"
        + "  - confirm: *x\n" * 300, "invalid", "too many aliases")
    marker = tmp / "pwned-absolute"
    put("absolute_marker", head + f"  - confirm: !!python/object/apply:os.system "
        f"['touch {marker}']\n  - wait: !!python/object/apply:builtins.open "
        f"['{marker}', 'w']\n", "invalid", "is not allowed")
    put("include_long_name", head + "  - include: " + "a" * 5000 + ".yaml\n",
        "invalid", "cannot use the path (File name too long)")
    put("include_chain", head + "  - include: chain1.yaml\n", "invalid", "nested more than")
    for i in range(1, 40):
        (seqs / f"chain{i}.yaml").write_text(f"name: c{i}\ndescription: d\nsteps:\n"
                                            f"  - include: chain{i + 1}.yaml\n")
    (seqs / "chain40.yaml").write_text("name: c40\ndescription: d\nsteps: [reset]\n")
    (seqs / "outside.yaml").symlink_to(ROOT / "sequences" / "startup.yaml")
    put("include_symlink_out", head + "  - include: outside.yaml\n",
        "invalid", "is outside the sequences folder")
    put("include_loop_three", head + "  - include: loop_b.yaml\n",
        "invalid", "include loop")
    (seqs / "loop_b.yaml").write_text("name: B\ndescription: d\nsteps: [{include: loop_c.yaml}]\n")
    (seqs / "loop_c.yaml").write_text(
        "name: C\ndescription: d\nsteps: [{include: include_loop_three.yaml}]\n")
    put("empty", b"", "invalid", "the file is empty")
    put("bom_only", b"\xef\xbb\xbf", "invalid", "the file is empty")
    directory = seqs / "a_directory.yaml"
    directory.mkdir()
    out["directory"] = (directory, "unusable", "")
    out["missing"] = (seqs / "missing.yaml", "unusable", "")
    return out


def test_generated_hostile_files(tmp_path, places):
    """Big, deep, numeric and path-based hostile files, generated into tmp_path."""
    sandbox, logs = places
    seqs = make_sequences(tmp_path / "project")
    for name, (path, want, words) in _generated(seqs, tmp_path).items():
        expected, v, r = check_file(path, sandbox=sandbox, logs=logs,
                                    markers=(tmp_path / "pwned-absolute",))
        assert expected == want, (name, v.describe())
        if want == "invalid":
            assert words in v.stdout.splitlines()[0], (name, v.describe())
        elif want == "valid":
            assert v.exit_code == 0 and r.exit_code == 0, (name, r.describe())


# ----------------------------------------------------------------------------- random files
#: Created in the cwd (the sandbox) by the payloads below, if anything ever ran them.
_FUZZ_MARKER = "pwned-fuzz"

_VALID = ["reset", "home", "set_limits", "halt", "move: totem", "move: park",
          "move: {pose: opsafe, velocity_scale: 0.5}", "move: {joints: {j1: 5}}",
          "move: {joints: {j1: -3, j5: 4}, relative: true}", "wait: 0.05",
          "wait: {until: in_position, timeout_s: 5}", "checkpoint: totem", "confirm: Ready?",
          "include: startup.yaml", "reset: [j1, j2]", "home: {joints: all, label: Home}",
          "move: {joints: {j7: 10}, label: 'Wrist 🤖'}"]
_MOTION = ["move: totem", "move: {pose: opsafe, velocity_scale: 0.5}", "move: {joints: {j1: 5}}",
           "move: {joints: {j1: -3, j5: 4}, relative: true}", "wait: 0.05",
           "wait: {until: in_position}", "checkpoint: totem", "confirm: Clear?",
           "move: {joints: {j7: 10}, velocity_deg_s: {j7: 20}}"]
_NUMBERS = ["1e400", "-1e400", ".nan", ".NaN", ".inf", "-.Inf", "1e-400", "-0.0",
            "1" + "0" * 1000, "0x" + "f" * 500, "9" * 400, "1_000", "0o17", "0x1F", "+12",
            "5e-324", "1.7976931348623157e308", "1e3", "12e", "0b101", "1:30", "'5'", "~"]
_WRONG = ["move: {joints: {j1: ten}}", "wait: [2]", "confirm: 42", "home: yes", "reset: 7",
          "move: {pose: totem, velocity_scale: fast}", "move: {joints: [j1, 5]}",
          "checkpoint: {position_mm: [1, 2]}", "set_limits: {limits_deg: {j1: [1, 2, 3]}}",
          "move: {pose: 12}", "wait: {seconds: '1'}", "move: {relative: on, joints: {j2: 1}}",
          "move", "wait", "- reset", "{}", "[]", "~", "move: {}",
          "move: {pose: totem, joints: {j1: 1}}"]
_UNKNOWN = ["mvoe: totem", "move: {pose: totem, velocty: 3}", "wait: {sconds: 1}", "jump: 3",
            "move: {pose: nowhere}", "move: {joints: {j9: 1}}", "move: {joints: {j3: 1}}",
            "include: nosuch.yaml", "include: ../escape.yaml", "include: /etc/passwd.yaml",
            "include: s.yaml", "include: startup.yml", "move: {pose: ../arms/lwa3}",
            "move: {pose: /etc/passwd}", "reset: {joints: [j8]}"]
_DEEP = [f"confirm: {'[' * n}{']' * n}" for n in (3, 62, 63, 64, 65, 200)] + [
    "move: " + "{a: " * 70 + "1" + "}" * 70]
_UNICODE = ['confirm: "\\ud800"', "confirm: a\u202eb", "confirm: 😀", "confirm: e\u0301",
            "confirm: \u200b", "confirm: \ufeffx", "confirm: a\u2028b", "confirm: a\x85b",
            "confirm: \U0010ffff", "confirm: a\x00b", "confirm: a\ufffeb", "confirm: a\x1bb",
            "confirm: \x7f", "m\u0301ove: totem", "ｍｏｖｅ: totem", "confirm: a\ud800b",
            "confirm: '\t'", "confirm: \"\\x00\""]
_ANCHORS = ["&a reset", "*a", "move: &p {pose: totem}", "move: *p", "confirm: &c Ready?",
            "confirm: *c", "*nowhere", "&r [*r]", "move: {<<: *p, velocity_scale: 0.5}",
            "&a home"]
_TAGS = [f"confirm: !!python/object/apply:os.system ['touch {_FUZZ_MARKER}']",
         f"!!python/object/apply:os.system ['touch {_FUZZ_MARKER}']",
         f"confirm: !<tag:yaml.org,2002:python/object/apply:os.system> ['touch {_FUZZ_MARKER}']",
         f"wait: !!python/object/apply:builtins.open ['{_FUZZ_MARKER}', 'w']",
         "confirm: !!python/name:os.system ''", "confirm: !!str 5", "wait: !!float 0.01",
         "wait: !!int x", "confirm: !custom x", "confirm: !!binary aGk=", "reset: !!null",
         "move: !!map {pose: totem}", "home: !!seq []", "confirm: !!set {a}"]
_HOSTILE = ([f"move: {{joints: {{j1: {n}}}}}" for n in _NUMBERS]
            + [f"wait: {n}" for n in (".nan", ".inf", "-1", "0", "1e400", "1e-400", "'1'",
                                      "5e-324", "0x" + "f" * 500)]
            + [f"move: {{pose: totem, velocity_deg_s: {{j2: {n}}}}}"
               for n in ("1e400", ".nan", "0", "-5", "1e-400", "5e-324", "1e308")]
            + [f"move: {{pose: totem, timeout_s: {n}}}" for n in ("1e308", "1e-300", ".inf")]
            + _WRONG + _UNKNOWN + _DEEP + _UNICODE + _ANCHORS + _TAGS)
_TOP = ["extra: 1", "arm: nosuch.yaml", "arm: ../../../../etc/passwd.yaml", "arm: 7",
        "name: [x]", "description: !!python/name:os.system ''", "steps: []", "steps:",
        "name: \u202e", "? [complex, key]\n: 1", "name: &n X", "description: *n"]
_NAMES = ["Fuzz", "'Fuzz'", '"F\\tuzz"', "Ünïcödé 🤖", "''", "~", "[a]", "42", "1e400",
          "x" * 300, "\u202etxt", "!!python/name:os.system ''"]
_PREFIX = ["", "", "", "\ufeff", "%YAML 1.2\n---\n", "%YAML 1.1\n---\n", "---\n",
           "%TAG !! tag:yaml.org,2002:python/\n---\n", "# comment\n"]


def _block(steps: list[str]) -> str:
    return "steps:\n" + "".join(f"  - {s}\n" for s in steps)


def _flow(steps: list[str]) -> str:
    return "steps: [" + ", ".join("{" + s + "}" if ": " in s else s for s in steps) + "]\n"


@st.composite
def sequence_texts(draw) -> str:
    kind = draw(st.sampled_from(["clean", "clean", "mixed", "mixed", "mixed", "raw"]))
    if kind == "clean":   # start-up first, then motion: most of these are valid and run
        steps = ["include: startup.yaml"] + draw(st.lists(st.sampled_from(_MOTION), max_size=3))
        if draw(st.booleans()):
            steps.insert(draw(st.integers(0, len(steps))), draw(st.sampled_from(_HOSTILE)))
        return (draw(st.sampled_from(["", "\ufeff"])) + "name: Fuzz\ndescription: random\n"
                + _block(steps))
    if kind == "mixed":
        steps = draw(st.lists(st.one_of(st.sampled_from(_VALID), st.sampled_from(_HOSTILE),
                                        st.text(max_size=12)), max_size=7))
        body = draw(st.sampled_from([_block, _block, _flow]))(steps)
        top = draw(st.lists(st.sampled_from(_TOP), max_size=2))
        text = (draw(st.sampled_from(_PREFIX)) + f"name: {draw(st.sampled_from(_NAMES))}\n"
                "description: random\n" + "".join(t + "\n" for t in top) + body)
    else:                 # fragments glued at random, plus arbitrary text
        parts = draw(st.lists(st.one_of(st.sampled_from(_HOSTILE + _TOP + _PREFIX),
                                        st.text(max_size=30)), min_size=1, max_size=8))
        text = "\n".join(parts)
    if draw(st.integers(0, 4)) == 0:  # junk spliced anywhere
        cut = draw(st.integers(0, len(text)))
        text = text[:cut] + draw(st.text(max_size=8)) + text[cut:]
    return text


@pytest.fixture(scope="module")
def fuzz_places(tmp_path_factory):
    root = tmp_path_factory.mktemp("fuzz")
    seqs = make_sequences(root / "project")
    (root / "cwd").mkdir()
    (root / "logs").mkdir()
    return seqs, root / "cwd", root / "logs"


@pytest.mark.slow  # 80 generated files, each validated and run
@settings(max_examples=int(os.environ.get("SEQRUN_FUZZ_EXAMPLES", "80")), deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(text=sequence_texts(), as_bytes=st.booleans())
# validate and run listed these errors in two orders (the pose file's error in between)
@example(text="name: Fuzz\ndescription: random\nsteps: [move: park, home]\n", as_bytes=False)
def test_random_sequence_files(fuzz_places, text, as_bytes):
    """Random documents from fragments: valid steps, wrong types, unknown keys, deep
    nesting, huge/NaN/inf numbers, odd unicode, anchors and aliases, tags."""
    seqs, sandbox, logs = fuzz_places
    path = seqs / "s.yaml"
    # As text (surrogates kept as the bytes an editor would write) or as Latin-1 bytes.
    data = (text.encode("latin-1", errors="replace") if as_bytes
            else text.encode("utf-8", errors="surrogatepass"))
    path.write_bytes(data)
    expected, v, r = check_file(path, sandbox=sandbox, logs=logs,
                                markers=(sandbox / _FUZZ_MARKER,))
    event(f"verdict {expected}, run exit {r.exit_code}")
    if expected == "valid":
        # The dry run of `validate` predicts the run (both: the executor on the simulator).
        assert (v.exit_code == 0) == (r.exit_code == 0), v.describe() + "\n" + r.describe()


#: A pose 0.68° beyond j4's lower limit (Park's -120.32): no move target, its error at its
#: own line (Park itself is a move target since issue 42).
BEYOND = {"j1": 0, "j2": -90, "j3": 0, "j4": -121, "j5": 0, "j6": 115.74, "j7": 0}


@pytest.mark.parametrize("text", [
    # Loads, so `run` reports the static validation's findings itself: the step order put
    # the pose file's error (the first step's target) between the two steps' own errors.
    "name: Fuzz\ndescription: random\nsteps: [move: beyond, home]\n",
    "name: Fuzz\ndescription: random\nsteps:\n  - move: beyond\n  - home\n"
    "  - move: {joints: {j9: 1}}\n",
    # The move below the pose file's error line: still the sequence's errors first.
    "name: Fuzz\ndescription: random\n" + "# padding\n" * 20 + "steps: [move: beyond, home]\n",
    # Does not load: both commands merge the load errors with the findings the same way.
    "steps: [move: beyond, home]\n",
], ids=["flow", "block", "far_down", "unloadable"])
def test_validate_and_run_list_errors_in_one_order(tmp_path, places, text):
    """Found by test_random_sequence_files: both commands list the errors in one order, by
    position within a file, the files in the order the steps reach them (the sequence
    before the pose file its move names)."""
    from seqrun.arm.poses import pose_document, pose_yaml

    sandbox, logs = places
    path = make_sequences(tmp_path / "project") / "s.yaml"
    arm = load_arm(tmp_path / "project" / "arms" / "lwa3.yaml")
    (tmp_path / "project" / "poses" / "beyond.yaml").write_text(
        pose_yaml(pose_document("beyond", arm, BEYOND, "beyond j4's travel", "manual")),
        encoding="utf-8")
    path.write_text(text, encoding="utf-8")
    _, v, _ = check_file(path, sandbox=sandbox, logs=logs)   # asserts run lists them alike
    errors = [LOCATED.match(line) for line in v.stdout.splitlines()[:-1]
              if ": note: " not in line]
    files = [m["file"] for m in errors]
    assert files == sorted(files, key=lambda f: not f.endswith("s.yaml")), v.describe()
    assert files[-1].endswith("beyond.yaml"), v.describe()
    own = [(int(m["line"]), int(m["col"])) for m in errors if m["file"].endswith("s.yaml")]
    assert own == sorted(own) and len(own) >= 2, v.describe()


# ----------------------------------------------------------------------------- (b) options
TOTEM = ROOT / "sequences" / "totem.yaml"
RUN = ["run", TOTEM, "--virtual-time", "--yes", "--plain"]
LONG = "a" * 5000


@pytest.mark.parametrize("args, words", [
    (["fk", "--pose", "nosuch"], "unknown pose 'nosuch'"),
    (["validate", "--start", "nosuch", TOTEM], "unknown pose 'nosuch'"),
    ([*RUN, "--sim-fault", "9:tow_error@1"], "no module 9"),
    ([*RUN, "--sim-fault", "4:melt@1"], "unknown kind 'melt'"),
    ([*RUN, "--sim-fault", "4:tow_error"], "missing '@SECONDS'"),
    ([*RUN, "--sim-fault", "4:drop_acks=2@0"], "rate must be in (0, 1]"),
    ([*RUN, "--sim-fault", "4:tow_error@-1"], "time must be >= 0"),
    ([*RUN, "--speed", "0"], "--speed must lie in (0, 1], got 0"),
    ([*RUN, "--speed", "1.5"], "--speed must lie in (0, 1], got 1.5"),
    ([*RUN, "--speed", "nan"], "--speed must lie in (0, 1], got nan"),
    (["run", "nosuch.yaml", "--virtual-time", "--yes", "--plain"], "nosuch.yaml not found"),
    (["validate", "nosuch.yaml"], "nosuch.yaml: no such file"),
    ([*RUN, "--from", "0"], "--from 0: the sequence has steps 1-"),
    ([*RUN, "--from", "99"], "--from 99: the sequence has steps 1-"),
    (["run", TOTEM, "--yes", "--plain", "--sim-fault", "4:tow_error@1", "-i", "socketcan"],
     "--sim-fault only applies to the simulator"),
    (["run", TOTEM, "--yes", "--plain", "--virtual-time", "-i", "socketcan"],
     "--virtual-time needs the simulator"),
    ([*RUN, "--command-mode", "teleport"], "--command-mode must be ramp or step"),
    ([*RUN, "--bus-kwargs", "nokeyvalue"], "--bus-kwargs expects KEY=VALUE"),
    ([*RUN, "--arm", "nosuch-arm.yaml"], "arm file nosuch-arm.yaml not found"),
    # Paths the operating system refuses (ENAMETOOLONG) are input errors, not crashes.
    (["validate", LONG + ".yaml"], "File name too long"),
    (["run", LONG + ".yaml", "--virtual-time", "--yes", "--plain"], "File name too long"),
    (["validate", TOTEM, "--arm", LONG + ".yaml"], "File name too long"),
    ([*RUN, "--arm", LONG + ".yaml"], "File name too long"),
    ([*RUN, "--log-dir", "/tmp/" + LONG], "cannot create the run folder"),
    ([*RUN, "--log-dir", TOTEM], "cannot create the run folder"),
    (["validate", ROOT / "docs"], "no sequence files"),
    (["run", ROOT / "sequences", "--virtual-time", "--yes", "--plain"], "not found"),
], ids=lambda a: " ".join(str(x)[:30] for x in a) if isinstance(a, list) else None)
def test_bad_command_line_is_one_error_line(args, words):
    r = invoke(*args, cwd=ROOT)
    assert_one_error_line(r)
    assert words in r.stderr, r.describe()
    assert r.spy.frames == [], r.describe()  # nothing was sent, on any bus


@pytest.mark.parametrize("spec, words", [("9:halt@1", "no module 9"),
                                         ("4:melt@1", "unknown kind 'melt'"),
                                         ("4:tow_error", "missing '@SECONDS'")])
def test_sim_serve_bad_fault_is_one_error_line(spec, words):
    from seqrun.sim.socketcand import SocketcandServer

    def no_serving(self):  # were the spec accepted, end at once instead of serving forever
        raise KeyboardInterrupt

    with mock.patch.object(SocketcandServer, "serve_forever", no_serving):
        r = invoke("sim", "serve", "--port", "0", "--fault", spec, cwd=ROOT)
    assert_one_error_line(r)
    assert words in r.stderr, r.describe()
    assert r.stdout == "", r.describe()

