"""Safe YAML -> pydantic, with every error at ``file:line:col`` (1-based).

Every YAML file seqrun reads (sequences, arm descriptions, poses) goes through here::

    bytes --(size limit, strict UTF-8)--> text
          --(yaml composer, own resolver, depth/alias limits)--> node tree
          --(own node -> Python conversion: tags, duplicate keys, alias expansion)--> data
          --(pydantic)--> model, each error's ``loc`` mapped back to its node

Nothing is ever *constructed* by PyYAML: the composer only builds nodes, and this module
turns nodes into ``dict``/``list``/``str``/``int``/``float``/``bool``/``None`` itself, so no
tag can create a Python object. Every problem becomes a :class:`~seqrun.errors.SourceError`;
a file's problems are raised together as one :class:`~seqrun.errors.SequenceInvalid`.
A file that cannot be read at all (missing, a directory, no permission) raises
:class:`~seqrun.errors.UserInputError` instead.

YAML 1.1 surprises (PyYAML's default resolver) are switched off: plain scalars are resolved
with the YAML 1.2 *core* schema, so

- only ``true``/``false`` (any capitalisation of those two words) are booleans; ``yes``,
  ``no``, ``on``, ``off``, ``y``, ``n`` stay text. Models use strict types, so where a
  boolean is expected, ``yes`` is an error ("expected true or false") and where text is
  expected (a prompt, a name) ``no`` is the word the author wrote;
- ``010`` is ten (not octal 8), ``0o17``/``0x1f`` are octal/hex, ``1e3`` is a number;
- ``1:30`` (1.1 base-60, i.e. 90) and ``2024-01-01`` (1.1 timestamp) stay text: a number
  field then says "expected a number, got '1:30'" with a hint;
- ``.nan``, ``.inf``, ``-.inf`` are read as floats so that the model can reject them with
  "expected a finite number"; ``nan``/``inf`` without the dot are text;
- merge keys (``<<``) are not supported (an error saying so); anchors and aliases are, within
  limits (:data:`MAX_ALIAS_USES`, :data:`MAX_EXPANDED_NODES`).

Only the core tags are allowed explicitly (``!!str``, ``!!int``, ``!!float``, ``!!bool``,
``!!null``, ``!!seq``, ``!!map``); ``!!python/...``, ``!!binary``, ``!!timestamp``, ``!!set``
and every local tag (``!foo``) are located errors.
"""

from __future__ import annotations

import contextlib
import difflib
import gc
import hashlib
import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from collections.abc import Iterator, Mapping
from typing import TYPE_CHECKING, Any, ClassVar, TypeVar

import yaml
from pydantic import BaseModel, TypeAdapter, ValidationError, model_validator
from pydantic_core import InitErrorDetails, PydanticCustomError
from yaml.events import AliasEvent, MappingStartEvent, SequenceStartEvent
from yaml.nodes import MappingNode, Node, ScalarNode, SequenceNode

from seqrun.errors import SequenceInvalid, SourceError, UserInputError
from seqrun.formatting import control_character

__all__ = [
    "MAX_ALIAS_USES",
    "MAX_DEPTH",
    "MAX_EXPANDED_NODES",
    "MAX_FILE_BYTES",
    "Document",
    "FriendlyModel",
    "Location",
    "display_path",
    "load_document",
    "load_model",
]

#: Largest file accepted (bytes). A sequence is a few kB; this stops accidents, not attacks.
MAX_FILE_BYTES = 1 << 20
#: Deepest nesting of mappings/lists (the sequence format needs 5).
MAX_DEPTH = 64
#: Most alias uses (``*name``) in one document.
MAX_ALIAS_USES = 200
#: Most values a document may expand to once aliases are followed (billion-laughs guard).
MAX_EXPANDED_NODES = 100_000
#: Longest integer literal read (a float's range ends near 1e308; Python converts and
#: prints at most 4300 digits).
MAX_INT_CHARS = 400

_CORE = "tag:yaml.org,2002:"
STR, INT, FLOAT, BOOL, NULL = (_CORE + t for t in ("str", "int", "float", "bool", "null"))
SEQ, MAP = _CORE + "seq", _CORE + "map"

_BOOL_RE = re.compile(r"^(?:true|True|TRUE|false|False|FALSE)$")
_INT_RE = re.compile(r"^(?:[-+]?[0-9]+|0o[0-7]+|0x[0-9a-fA-F]+)$")
_FLOAT_RE = re.compile(r"^(?:[-+]?(?:\.[0-9]+|[0-9]+(?:\.[0-9]*)?)(?:[eE][-+]?[0-9]+)?"
                       r"|[-+]?\.(?:inf|Inf|INF)|\.(?:nan|NaN|NAN))$")
_NULL_RE = re.compile(r"^(?:~|null|Null|NULL|)$")
_SEXAGESIMAL_RE = re.compile(r"^[-+]?[0-9][0-9_]*(?::[0-5]?[0-9])+(?:\.[0-9_]*)?$")
_YAML11_BOOLS = {"yes", "no", "on", "off", "y", "n"}


# ----------------------------------------------------------------------------- locations
@dataclass(frozen=True)
class Location:
    """A place in a source file, 1-based line and column."""

    file: str
    line: int
    column: int

    def error(self, message: str) -> SourceError:
        return SourceError(self.file, self.line, self.column, message)

    def __str__(self) -> str:
        return f"{self.file}:{self.line}:{self.column}"


def display_path(path: str | os.PathLike[str]) -> str:
    """How a file is named in messages: relative to the working directory when it lies
    below it, else absolute."""
    p = Path(path)
    try:
        absolute = p.resolve()
        return str(absolute.relative_to(Path.cwd().resolve()))
    except (ValueError, OSError, RuntimeError):  # elsewhere, or unresolvable (symlink loop)
        return str(p)


class _Problem(Exception):
    """A located problem found while composing or converting (internal)."""

    def __init__(self, mark: yaml.Mark | None, message: str) -> None:
        super().__init__(message)
        self.mark = mark
        self.message = message


# ----------------------------------------------------------------------------- composing
class _Alias:
    """An alias use (``*name``) in the node tree: the anchored node plus where it was used."""

    __slots__ = ("name", "start_mark", "target")

    def __init__(self, target: Node | None, start_mark: yaml.Mark, name: str) -> None:
        self.target = target
        self.start_mark = start_mark
        self.name = name


if TYPE_CHECKING:  # what _Limits is mixed into: a parser and PyYAML's composer
    _Composing = yaml.SafeLoader
else:
    _Composing = object


class _Limits(_Composing):
    """The composer's limits (depth, alias uses), shared by both loaders below: the node
    tree is always built by PyYAML's Python composer with this hook."""

    _depth: int
    _alias_uses: int

    def compose_node(self, parent, index):
        if self.check_event(AliasEvent):
            event = self.peek_event()
            self._alias_uses += 1
            if self._alias_uses > MAX_ALIAS_USES:
                raise _Problem(event.start_mark,
                               f"too many aliases (more than {MAX_ALIAS_USES} uses of '*name')")
            node = super().compose_node(parent, index)
            return _Alias(node, event.start_mark, event.anchor)
        nesting = self.check_event(MappingStartEvent, SequenceStartEvent)
        if nesting:
            self._depth += 1
            if self._depth > MAX_DEPTH:
                raise _Problem(self.peek_event().start_mark,
                               f"nested too deeply (more than {MAX_DEPTH} levels)")
        try:
            return super().compose_node(parent, index)
        finally:
            if nesting:
                self._depth -= 1


class _Loader(_Limits, yaml.SafeLoader):
    """SafeLoader with the YAML 1.2 core resolver and limits; used for composing only."""

    yaml_implicit_resolvers: dict = {}

    def __init__(self, stream: str) -> None:
        super().__init__(stream)
        self._depth = 0
        self._alias_uses = 0


_Loader.add_implicit_resolver(BOOL, _BOOL_RE, list("tTfF"))
_Loader.add_implicit_resolver(INT, _INT_RE, list("-+0123456789"))
_Loader.add_implicit_resolver(FLOAT, _FLOAT_RE, list("-+0123456789."))
_Loader.add_implicit_resolver(NULL, _NULL_RE, ["~", "n", "N", ""])

try:  # libyaml's scanner and parser, when PyYAML was built with it (its wheels are)
    from yaml._yaml import CParser as _CParser
except ImportError:  # pragma: no cover - depends on how PyYAML was installed
    _CParser = None  # type: ignore[assignment,misc]

#: Compose with libyaml's parser when it is there (6x faster on large files); the
#: pure-Python one is used without it, and for every file libyaml refuses or that holds
#: characters YAML forbids, so that messages and positions are the same either way.
USE_LIBYAML = _CParser is not None
#: Where libyaml and PyYAML disagree on what is valid YAML (found by comparing the two on
#: random text, tests/test_yaml_parsers.py): characters PyYAML's reader refuses
#: (yaml.reader.Reader.NON_PRINTABLE), tabs (libyaml reads "a<TAB>" as the text "a"),
#: byte-order marks after the start, a block scalar header followed by '#' ("|#"),
#: directives ("%YAML 1.1#"), and '?' after a '[' or '{' (PyYAML ends a plain scalar at
#: '?' inside [ ] and { }, libyaml does not), and tags (they scan tag handles apart; seqrun
#: refuses all but the core ones anyway).
#: Such files are read by the Python parser only, which names the problem as before.
#: (The pattern of all of them; :func:`_python_only` searches its parts one by one.)
_PYTHON_ONLY = ("[^\x09\x0A\x0D\x20-\x7E\x85\xA0-\uD7FF\uE000-\uFFFD"
                "\U00010000-\U0010ffff]|[\t\ufeff]|[|>][-+0-9]*#|^%"
                "|(?:^|[\\s\\[{,:])![^\\s]")

if _CParser is not None:
    class _CLoader(_Limits, yaml.composer.Composer, _CParser, yaml.resolver.BaseResolver):
        """libyaml's events, PyYAML's Python composer (with the limits), our resolver."""

        yaml_implicit_resolvers: dict = _Loader.yaml_implicit_resolvers

        def __init__(self, stream: str) -> None:
            _CParser.__init__(self, stream)
            yaml.composer.Composer.__init__(self)
            yaml.resolver.BaseResolver.__init__(self)
            self._depth = 0
            self._alias_uses = 0
            self.empty_scalars = False

        def compose_scalar_node(self, anchor):
            node = super().compose_scalar_node(anchor)
            if not node.value and not node.style:
                # libyaml puts an empty value elsewhere than PyYAML does ("a: {b: }"):
                # such a file is composed again by the Python parser, for its positions.
                self.empty_scalars = True
            return node


#: :data:`_PYTHON_ONLY` in parts, each searched fast: PyYAML's own pattern of the characters
#: its reader refuses (compiled once already: a set of ranges up to U+10FFFF is slow to
#: compile), the other parts after the check that the character each
#: needs is there. As one alternation the engine tried every branch at every character of
#: every file read. Same answer (tests/test_yamlsource.py compares them).
_BLOCK_HEADER_COMMENT = re.compile("[|>][-+0-9]*#")
_DIRECTIVE = re.compile("^%", re.MULTILINE)
_TAG = re.compile("(?:^|[\\s\\[{,:])![^\\s]", re.MULTILINE)


def _python_only(text: str) -> bool:
    """Whether ``text`` has one of the constructs of :data:`_PYTHON_ONLY` (linear time)."""
    if ("\t" in text or "\ufeff" in text or yaml.reader.Reader.NON_PRINTABLE.search(text)
            or ("#" in text and _BLOCK_HEADER_COMMENT.search(text))
            or ("%" in text and _DIRECTIVE.search(text))
            or ("!" in text and _TAG.search(text))):
        return True
    question = text.rfind("?")
    if question < 0:
        return False
    brackets = [i for i in (text.find("["), text.find("{")) if i >= 0]
    return bool(brackets) and min(brackets) < question


def compose(text: str, *, libyaml: bool | None = None) -> Node | None:
    """The node tree of ``text`` (None for a document without content). Raises
    :class:`_Problem` for the limits and ``yaml.YAMLError`` for syntax, the same way
    whichever parser ran (``libyaml``: default :data:`USE_LIBYAML`)."""
    use_c = USE_LIBYAML if libyaml is None else (libyaml and _CParser is not None)
    if use_c and not _python_only(text):
        loader = _CLoader(text)
        try:
            node = loader.get_single_node()
            if not loader.empty_scalars:
                return node
        except _Problem:
            raise
        except Exception:  # noqa: BLE001 - libyaml refused it: the Python parser says why
            pass           # in its own words (and refuses or accepts it as it always has)
        finally:
            loader.dispose()
    return yaml.compose(text, Loader=_Loader)


def _short_tag(tag: str) -> str:
    return "!!" + tag[len(_CORE):] if tag.startswith(_CORE) else tag


def _scalar(node: ScalarNode) -> Any:
    tag, text = node.tag, node.value
    if tag == STR:
        bad = control_character(text)
        if bad is not None:   # it would reach the operator's terminal
            raise _Problem(node.start_mark, f"a control character ({bad}) in a text: seqrun "
                                            "files hold printable text (tabs and line breaks "
                                            "aside)")
        return text
    checks = {BOOL: _BOOL_RE, INT: _INT_RE, FLOAT: _FLOAT_RE, NULL: _NULL_RE}
    if tag not in checks:
        raise _Problem(node.start_mark, f"tag '{_short_tag(tag)}' is not allowed: seqrun files "
                                        "are plain YAML (allowed tags: !!str, !!int, !!float, "
                                        "!!bool, !!null)")
    if not checks[tag].match(text):
        raise _Problem(node.start_mark, f"'{text}' is not a valid {_short_tag(tag)}")
    if tag == BOOL:
        return text.lower() == "true"
    if tag == NULL:
        return None
    if tag == INT:
        if len(text) > MAX_INT_CHARS:  # Python would refuse to convert or print it
            raise _Problem(node.start_mark, f"a whole number of {len(text)} characters is "
                                            f"too long (at most {MAX_INT_CHARS})")
        return int(text, 0) if text[:2] in ("0o", "0x") else int(text, 10)
    lowered = text.lower()
    if lowered.endswith(".inf"):
        return -math.inf if lowered.startswith("-") else math.inf
    if lowered == ".nan":
        return math.nan
    return float(text)


class _Converter:
    """Node tree -> plain Python data, with an index of every mapping's keys for locating.

    Problems that leave the rest of the document readable (a bad tag, a duplicate key, a
    merge key) are collected in :attr:`problems` and conversion goes on, so an author sees
    all of them at once; limits and recursion stop it (raise :class:`_Problem`).
    """

    def __init__(self) -> None:
        self.expanded = 0
        self.index: dict[int, dict[Any, tuple[Node, Any]]] = {}
        self.problems: list[_Problem] = []
        self._active: set[int] = set()
        self._aliases: list[_Alias] = []

    def convert(self, node: Any) -> Any:
        if isinstance(node, _Alias):
            self._aliases.append(node)
            try:
                return self.convert(node.target)
            finally:
                self._aliases.pop()
        self.expanded += 1
        if self.expanded > MAX_EXPANDED_NODES:
            mark = self._aliases[0].start_mark if self._aliases else node.start_mark
            raise _Problem(mark, f"the document expands to more than {MAX_EXPANDED_NODES} "
                                 "values through its aliases (an alias bomb?); write it out")
        if isinstance(node, ScalarNode):
            try:
                return _scalar(node)
            except _Problem as exc:
                self.problems.append(exc)
                return None
        if id(node) in self._active:
            alias = self._aliases[-1] if self._aliases else None
            mark = alias.start_mark if alias is not None else node.start_mark
            name = f" '*{alias.name}'" if alias is not None else ""
            raise _Problem(mark, f"recursive alias{name}: an anchored value contains itself")
        if node.tag not in (SEQ, MAP):
            self.problems.append(_Problem(node.start_mark, f"tag '{_short_tag(node.tag)}' is "
                                                           "not allowed: seqrun files are "
                                                           "plain YAML"))
        self._active.add(id(node))
        try:
            if isinstance(node, SequenceNode):
                return [self.convert(item) for item in node.value]
            return self._mapping(node)
        finally:
            self._active.discard(id(node))

    def _mapping(self, node: MappingNode) -> dict:
        result: dict[Any, Any] = {}
        keys: dict[Any, tuple[Node, Any]] = {}
        for key_node, value_node in node.value:
            if isinstance(key_node, _Alias) or not isinstance(key_node, ScalarNode):
                self.problems.append(_Problem(key_node.start_mark,
                                              "a key must be a plain word or number, "
                                              "not a list, mapping or alias"))
                continue
            try:
                key = _scalar(key_node)
            except _Problem as exc:
                self.problems.append(exc)
                continue
            if key == "<<" and not key_node.style:
                self.problems.append(_Problem(key_node.start_mark, "merge keys ('<<') are not "
                                                                   "supported: write the keys "
                                                                   "out"))
                continue
            marker = (type(key), key)
            if marker in keys:
                first = keys[marker][0].start_mark
                self.problems.append(_Problem(
                    key_node.start_mark,
                    f"duplicate key '{key}' (first given at line {first.line + 1})"))
                continue
            keys[marker] = (key_node, value_node)
            result[key] = self.convert(value_node)
        self.index[id(node)] = keys
        return result


# ----------------------------------------------------------------------------- documents
@dataclass
class Document:
    """One parsed YAML file: its node tree, its data, and error locating.

    ``file`` is the name used in messages (see :func:`display_path`).
    """

    path: Path
    file: str
    root: Node
    data: Any
    _index: dict[int, dict[Any, tuple[Node, Any]]] = field(repr=False, default_factory=dict)
    #: SHA-256 (hex) of the bytes read: what a run records of the files it validated.
    sha256: str = ""
    #: The bytes read: a run folder's copy of the file is these, never the file read again.
    source: bytes = field(repr=False, default=b"")

    # -- locating
    def location(self, node: Any) -> Location:
        mark = node.start_mark
        return Location(self.file, mark.line + 1, mark.column + 1)

    def find(self, loc: tuple | list, *, start: Any = None, key: bool = False) -> Any:
        """The node at a path of keys/indexes (pydantic ``loc`` or a plain path).

        Parts that name no key or index of the current node (union tags, class names) are
        skipped, so a path that runs out early ends at the deepest node that exists -- for
        a missing key, its parent mapping. ``key=True`` returns the key node of the last
        mapping entry followed instead of its value (unknown keys, bad dictionary keys).
        """
        node = self.root if start is None else start
        key_node = None
        for part in loc:
            real = node.target if isinstance(node, _Alias) else node
            if part == "[key]" and key_node is not None:
                key = True
                continue
            if isinstance(real, MappingNode) and isinstance(part, (str, int, float, bool)):
                entry = self._index.get(id(real), {}).get((type(part), part))
                if entry is not None:
                    key_node, node = entry
                    continue
            if (isinstance(real, SequenceNode) and isinstance(part, int)
                    and not isinstance(part, bool) and 0 <= part < len(real.value)):
                node, key_node = real.value[part], None
                continue
        if key and key_node is not None:
            return key_node
        return node

    def locate(self, loc: tuple | list, *, start: Any = None, key: bool = False) -> Location:
        return self.location(self.find(loc, start=start, key=key))

    def error(self, loc: tuple | list, message: str, *, start: Any = None,
              key: bool = False) -> SourceError:
        return self.locate(loc, start=start, key=key).error(message)

    def child(self, node: Any, key: Any) -> Any:
        """The value node of ``key`` in a mapping node (None if absent)."""
        real = node.target if isinstance(node, _Alias) else node
        entry = self._index.get(id(real), {}).get((type(key), key))
        return None if entry is None else entry[1]

    def items(self, node: Any) -> list[Any]:
        """The item nodes of a sequence node ([] for anything else)."""
        real = node.target if isinstance(node, _Alias) else node
        return list(real.value) if isinstance(real, SequenceNode) else []

    # -- validating
    def validate(self, model: type[M], *, context: dict[str, Any] | None = None) -> M:
        """Validate :attr:`data` against a model (or any type); raises SequenceInvalid.
        ``context``: pydantic's validation context (a sequence's parameters)."""
        try:
            if isinstance(model, type) and issubclass(model, BaseModel):
                return model.model_validate(self.data, context=context)
            return TypeAdapter(model).validate_python(self.data, context=context)
        except ValidationError as exc:
            raise SequenceInvalid(self.validation_errors(exc)) from None

    def validation_errors(self, exc: ValidationError, *, start: Any = None,
                          prefix: tuple = ()) -> list[SourceError]:
        """Every pydantic error as a located, reworded SourceError (sorted, deduplicated)."""
        errors = []
        for err in exc.errors(include_url=False):
            loc = tuple(prefix) + tuple(err["loc"])
            at_key = err["type"] in ("extra_forbidden", "unknown_key") or "[key]" in loc
            node = self.find(loc, start=start, key=at_key)
            parent = self._parent_name(loc, start)
            errors.append(self.location(node).error(friendly_message(err, parent)))
        return sort_errors(errors)

    def _parent_name(self, loc: tuple, start: Any) -> str:
        """The YAML key under which the error sits, for "unknown key 'x' in move"."""
        node = self.root if start is None else start
        name = ""
        for part in loc[:-1]:
            real = node.target if isinstance(node, _Alias) else node
            if isinstance(real, MappingNode) and isinstance(part, (str, int, float, bool)):
                entry = self._index.get(id(real), {}).get((type(part), part))
                if entry is not None:
                    node, name = entry[1], str(part)
                    continue
            if isinstance(real, SequenceNode) and isinstance(part, int) and not isinstance(
                    part, bool) and 0 <= part < len(real.value):
                node, name = real.value[part], f"{name} item {part + 1}".strip()
        return name


M = TypeVar("M")


def sort_errors(errors: list[SourceError]) -> list[SourceError]:
    """Deduplicate and order errors by position within each file; files stay in the order
    their first error was found (the including file before the included one)."""
    unique = list(dict.fromkeys(errors))
    first = {e.file: i for i, e in reversed(list(enumerate(unique)))}
    return sorted(unique, key=lambda e: (first[e.file], e.line, e.column))


def read_text(path: Path, file: str) -> str:
    """The file's text: UTF-8, at most :data:`MAX_FILE_BYTES`, a leading BOM dropped."""
    return read_source(path, file)[0]


def read_source(path: Path, file: str) -> tuple[str, str]:
    """``(text, sha256 of the bytes)`` of a file, checked as :func:`read_text` says."""
    text, data = read_checked(path, file)
    return text, hashlib.sha256(data).hexdigest()


def read_checked(path: Path, file: str) -> tuple[str, bytes]:
    """``(text, the bytes read)`` of a file, checked as :func:`read_text` says."""
    path = Path(path)
    try:
        if path.is_dir():
            raise UserInputError(f"{file}: is a directory, not a file")
        if path.exists() and not path.is_file():
            raise UserInputError(f"{file}: not a regular file")
        with path.open("rb") as stream:  # never more than the limit, whatever the file is
            data = stream.read(MAX_FILE_BYTES + 1)
    except FileNotFoundError:
        raise UserInputError(f"{file}: no such file") from None
    except (OSError, ValueError) as exc:
        reason = getattr(exc, "strerror", None) or str(exc)
        raise UserInputError(f"{file}: cannot read it ({reason})") from None
    if len(data) > MAX_FILE_BYTES:
        raise SequenceInvalid([SourceError(file, 1, 1, f"file too large (more than "
                                                        f"{MAX_FILE_BYTES} bytes)")])
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        pos = exc.start
        line = data.count(b"\n", 0, pos) + 1
        line_start = data.rfind(b"\n", 0, pos) + 1
        column = len(data[line_start:pos].decode("utf-8", errors="replace")) + 1
        raise SequenceInvalid([SourceError(
            file, line, column, f"not UTF-8 text: byte 0x{data[pos]:02x} cannot be decoded "
                                "(save the file as UTF-8)")]) from None
    text = text.removeprefix("\ufeff")
    if not text.strip():
        raise SequenceInvalid([SourceError(file, 1, 1, "the file is empty")])
    return text, data


#: PyYAML's problem texts that a test engineer would not understand, reworded.
_SYNTAX_HINTS = {
    "expected <block end>, but found '<block mapping start>'":
        "bad indentation: this line does not line up with the keys above it",
    "expected <block end>, but found '<block sequence start>'":
        "bad indentation: this list item does not line up with the items above it",
    "expected <block end>, but found '-'":
        "bad indentation: this list item does not line up with the items above it",
    "expected <block end>":
        "bad indentation, or a missing '-' or ':' before this",
    "mapping values are not allowed here":
        "unexpected ':' (a text containing ': ' must be quoted; a nested mapping starts on "
        "a new, further indented line)",
    "found unexpected end of stream":
        "the file ends inside a quoted text (a closing quote is missing)",
    "expected ',' or '}', but got '<stream end>'":
        "the file ends inside { ... }: a closing '}' is missing",
    "expected ',' or ']', but got '<stream end>'":
        "the file ends inside [ ... ]: a closing ']' is missing",
    "could not find expected ':'":
        "expected ':' after a key (or the line before is not finished)",
}


#: PyYAML's context texts, as "(<this> line N)".
_SYNTAX_CONTEXTS = {
    "while parsing a block mapping": "in the mapping that starts at",
    "while parsing a block collection": "in the list that starts at",
    "while parsing a flow mapping": "in the '{' of",
    "while parsing a flow sequence": "in the '[' of",
    "while scanning a quoted scalar": "the quoted text starts at",
    "while scanning a simple key": "in the key at",
}


def _syntax_key(problem: str) -> str:
    if problem in _SYNTAX_HINTS:
        return problem
    if problem.startswith("expected <block end>"):
        return "expected <block end>"
    return problem


def _syntax_error(file: str, exc: yaml.YAMLError, text: str) -> SourceError:
    if isinstance(exc, yaml.reader.ReaderError):
        pos = exc.position
        line = text.count("\n", 0, pos) + 1
        column = pos - (text.rfind("\n", 0, pos) + 1) + 1
        char = exc.character if isinstance(exc.character, str) else chr(exc.character)
        return SourceError(file, line, column,
                           f"character U+{ord(char):04X} is not allowed in a YAML file")
    if isinstance(exc, yaml.MarkedYAMLError):
        mark = exc.problem_mark or exc.context_mark
        problem = exc.problem or exc.context or "invalid YAML"
        if problem == "but found another document":
            problem = "only one YAML document per file: found a second one ('---')"
        else:
            problem = _SYNTAX_HINTS.get(_syntax_key(problem), problem)
            if exc.context and exc.context_mark is not None and exc.context_mark is not mark:
                what = _SYNTAX_CONTEXTS.get(exc.context, exc.context + " at")
                problem = f"{problem} ({what} line {exc.context_mark.line + 1})"
        if "'\\t'" in problem:
            problem += "; YAML does not allow tabs for indentation"
        if mark is not None:
            return SourceError(file, mark.line + 1, mark.column + 1, problem)
        return SourceError(file, 1, 1, problem)
    return SourceError(file, 1, 1, f"invalid YAML: {exc}")


@contextlib.contextmanager
def _no_gc_pauses() -> Iterator[None]:
    """No cyclic garbage collection while a tree is built: every node is new and alive, so
    the collector would only walk them again and again (half the time of a large file).
    The size and expansion limits bound what is allocated meanwhile."""
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()


def load_document(path: str | os.PathLike[str], *, file: str | None = None) -> Document:
    """Read, compose and convert one YAML file.

    Raises :class:`UserInputError` if it cannot be read, :class:`SequenceInvalid` for
    every YAML-level problem (encoding, syntax, tags, duplicate keys, aliases, limits).
    """
    path = Path(path)
    file = file if file is not None else display_path(path)
    text, source = read_checked(path, file)
    with _no_gc_pauses():
        try:
            root = compose(text)  # nodes only: nothing is constructed
        except _Problem as exc:
            raise SequenceInvalid([_problem_error(file, exc)]) from None
        except yaml.YAMLError as exc:
            raise SequenceInvalid([_syntax_error(file, exc, text)]) from None
        if root is None:
            raise SequenceInvalid([SourceError(file, 1, 1, "the file has no content "
                                                           "(only comments)")])
        converter = _Converter()
        try:
            data = converter.convert(root)
        except _Problem as exc:
            raise SequenceInvalid([_problem_error(file, exc)]) from None
    if converter.problems:
        raise SequenceInvalid(sort_errors([_problem_error(file, p) for p in converter.problems]))
    return Document(path=path, file=file, root=root, data=data, _index=converter.index,
                    sha256=hashlib.sha256(source).hexdigest(), source=source)


def _problem_error(file: str, exc: _Problem) -> SourceError:
    mark = exc.mark
    if mark is None:
        return SourceError(file, 1, 1, exc.message)
    return SourceError(file, mark.line + 1, mark.column + 1, exc.message)


def load_model(path: str | os.PathLike[str], model: type[M], *, file: str | None = None) -> M:
    """Load a YAML file into ``model``; raises :class:`SequenceInvalid` (located errors) or
    :class:`UserInputError` (unreadable file)."""
    return load_document(path, file=file).validate(model)


# ----------------------------------------------------------------------------- messages
def show(value: Any) -> str:
    """A value as the author wrote it in YAML, for messages."""
    if value is None:
        return "nothing (null)"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        if math.isnan(value):
            return ".nan"
        if math.isinf(value):
            return ".inf" if value > 0 else "-.inf"
        return f"{value:g}"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, str):
        text = value if len(value) <= 40 else value[:37] + "..."
        return f"'{text}'"
    if isinstance(value, dict):
        return "a mapping"
    if isinstance(value, (list, tuple)):
        return "a list"
    return type(value).__name__


def _number_hint(value: Any) -> str:
    if isinstance(value, str):
        if _SEXAGESIMAL_RE.match(value.strip()):
            return (" (seqrun reads YAML 1.2: '1:30' is text, not the base-60 number 90; "
                    "write the value in degrees or seconds)")
        if value.strip().lower() in ("nan", "inf", "+inf", "-inf", "infinity"):
            return " (NaN and infinity are not allowed)"
        if re.match(r"^[-+]?[0-9.]+$", value.strip()):
            return " (remove the quotes)"
    return ""


def friendly_message(err: Mapping[str, Any], parent: str = "") -> str:
    """A pydantic error dict reworded for a test engineer."""
    kind, value, ctx = err["type"], err.get("input"), err.get("ctx") or {}
    where = f" in {parent}" if parent else ""
    last = err["loc"][-1] if err["loc"] else ""
    if kind == "missing":
        return f"missing required key '{last}'{where}"
    if kind == "extra_forbidden":
        return f"unknown key '{last}'{where}"
    if kind in ("string_type", "str_type"):
        hint = " (put it in quotes if you mean text)" if isinstance(value, (int, float)) else ""
        return f"expected text, got {show(value)}{hint}"
    if kind in ("float_type", "float_parsing", "int_type", "int_parsing", "int_from_float"):
        what = "a whole number" if kind.startswith("int") else "a number"
        if isinstance(value, bool):
            return f"expected {what}, got {show(value)}"
        return f"expected {what}, got {show(value)}{_number_hint(value)}"
    if kind == "finite_number":
        return f"expected a finite number, got {show(value)} (NaN and infinity are not allowed)"
    if kind in ("bool_type", "bool_parsing"):
        hint = ""
        if isinstance(value, str) and value.lower() in _YAML11_BOOLS:
            hint = " (seqrun reads YAML 1.2: yes/no/on/off are words, not booleans)"
        return f"expected true or false, got {show(value)}{hint}"
    if kind == "literal_error":
        return f"expected {ctx.get('expected', 'one of the allowed values')}, got {show(value)}"
    bounds = {"greater_than": ("greater than", "gt"), "greater_than_equal": ("at least", "ge"),
              "less_than": ("less than", "lt"), "less_than_equal": ("at most", "le")}
    if kind in bounds:
        text, key = bounds[kind]
        bound = ctx.get(key)
        return f"must be {text} {show(bound) if isinstance(bound, float) else bound}, " \
               f"got {show(value)}"
    if kind in ("too_short", "too_long"):
        lo, hi = ctx.get("min_length"), ctx.get("max_length")
        n = ctx.get("actual_length")
        if kind == "too_short" and lo is not None and lo <= 1:
            return "must not be empty"
        if kind == "too_short":
            return f"needs at least {lo} values, got {n}"
        return f"takes at most {hi} values, got {n}"
    if kind == "string_too_short":
        return "must not be empty"
    if kind in ("list_type", "tuple_type", "set_type"):
        return f"expected a list, got {show(value)}"
    if kind in ("dict_type", "model_type", "model_attributes_type", "dataclass_type"):
        return f"expected a mapping (key: value), got {show(value)}"
    if kind == "value_error":
        return str(err["msg"]).removeprefix("Value error, ")
    if kind == "assertion_error":
        return str(err["msg"]).removeprefix("Assertion failed, ")
    return str(err["msg"])


# ----------------------------------------------------------------------------- models
class FriendlyModel(BaseModel):
    """Base for file models: an unknown key names the allowed keys (and the likely typo).

    ``yaml_name`` is what the author calls the mapping ("move", "the sequence").
    """

    yaml_name: ClassVar[str] = ""

    @model_validator(mode="wrap")
    @classmethod
    def _explain_unknown_keys(cls, data: Any, handler: Any) -> Any:
        try:
            return handler(data)
        except ValidationError as exc:
            details: list[Any] = []
            changed = False
            for err in exc.errors(include_url=False):
                if err["type"] == "missing" and len(err["loc"]) == 1 and cls.yaml_name:
                    details.append(InitErrorDetails(
                        type=PydanticCustomError("missing_key", "{text}", {
                            "text": f"missing required key '{err['loc'][0]}' in "
                                    f"{cls.yaml_name}"}),
                        loc=err["loc"], input=err["input"]))
                    changed = True
                elif err["type"] == "extra_forbidden" and len(err["loc"]) == 1:
                    details.append(InitErrorDetails(
                        type=PydanticCustomError("unknown_key", "{text}",
                                                 {"text": cls.unknown_key_message(
                                                     str(err["loc"][0]))}),
                        loc=err["loc"], input=err["input"]))
                    changed = True
                else:  # re-raised as it was (custom types must be error objects again)
                    details.append(InitErrorDetails(
                        type=PydanticCustomError(err["type"], err["msg"], err.get("ctx")),
                        loc=err["loc"], input=err["input"]))
            if not changed:
                raise
            raise ValidationError.from_exception_data(exc.title, details) from None

    @classmethod
    def unknown_key_message(cls, key: str) -> str:
        # the keys as written in a file (a field's alias where it has one: 'while')
        # the keys every step has, after the step's own
        last = ("monitors", "verifies", "tags", "if", "skip_if", "repeat", "retry", "on_fail",
                "breakpoint", "label")
        allowed = sorted((field.alias or name for name, field in cls.model_fields.items()),
                         key=lambda name: last.index(name) + 1 if name in last else 0)
        where = f" in {cls.yaml_name}" if cls.yaml_name else ""
        close = difflib.get_close_matches(key, allowed, n=1, cutoff=0.6)
        hint = f"did you mean '{close[0]}'? " if close else ""
        return f"unknown key '{key}'{where} ({hint}allowed: {', '.join(allowed)})"
