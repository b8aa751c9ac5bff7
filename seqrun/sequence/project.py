"""Campaign folders: where a sequence's poses, arm file and includes come from.

A campaign is a folder with a ``seqrun.toml`` (``seqrun init DIR`` makes one)::

    seqrun.toml      which arm, bus settings, run folder location
    sequences/       the campaign's sequences (includes may reach anywhere in the folder)
    poses/           the campaign's poses: added to the shipped ones, overriding same names
    arms/            (optional) the campaign's own arm files

A sequence belongs to the nearest ``seqrun.toml`` above it, or to the folder named with
``--project DIR``. Without a campaign the old layout still works: the nearest folder with
``arms/`` or ``poses/`` (the seqrun checkout itself), else the current directory. Either
way the shipped poses and arms (:mod:`seqrun.shipped`) come last in every search, so a
non-editable install finds them from anywhere. Every failed lookup names the places searched.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from seqrun.errors import SourceError, UserInputError
from seqrun.shipped import DEFAULT_ARM_NAME, shipped_arm, shipped_dir

if TYPE_CHECKING:
    from seqrun.sequence.campaign_config import CampaignConfig

#: The campaign's config file name.
CONFIG_NAME = "seqrun.toml"


class ConfigInvalid(UserInputError):
    """A broken ``seqrun.toml``: bad input (exit 2), said as ``file:line:col: message``."""

    def __init__(self, errors: list[SourceError]) -> None:
        self.errors = errors
        super().__init__("\n".join(str(e) for e in errors))


def _config_location(text: str, loc: tuple) -> tuple[int, int]:
    """Line and column of a key path such as ('bus', 'bitrate') or ('arms', 'B', 'bus',
    'channel') in TOML text (best effort: the key's line inside its table, the longest table
    first, else the table header, else 1:1)."""
    lines = text.splitlines()
    keys = [str(k) for k in loc if not isinstance(k, int)]
    headers: dict[str, int] = {}
    for cut in range(len(keys) - 1, -1, -1):
        want_table = ".".join(keys[:cut]) or None
        want_key = keys[cut]
        table: str | None = None
        for number, raw in enumerate(lines, start=1):
            line = raw.strip()
            match = re.match(r"^\[\s*([^\]]+?)\s*\]", line)
            if match:
                table = re.sub(r"\s*\.\s*", ".", match.group(1))
                headers.setdefault(table, number)
                continue
            key = re.match(r"^([A-Za-z0-9_\-\"']+)\s*=", line)
            if key and key.group(1).strip("\"'") == want_key and table == want_table:
                return number, raw.index(key.group(1)) + 1
    for cut in range(len(keys), 0, -1):
        if ".".join(keys[:cut]) in headers:
            return headers[".".join(keys[:cut])], 1
    return (1, 1)


#: How deep arrays and inline tables of a seqrun.toml may nest (a real one needs 2; a
#: "nesting bomb" would exhaust the parser's recursion).
MAX_CONFIG_NESTING = 32


def _too_deep(text: str) -> tuple[int, int] | None:
    """Line and column where arrays / inline tables nest deeper than
    :data:`MAX_CONFIG_NESTING` (strings and comments skipped), else None."""
    depth, quote, line, column = 0, "", 1, 0
    i, n = 0, len(text)
    while i < n:
        ch = text[i]
        column += 1
        if ch == "\n":
            line, column = line + 1, 0
            if quote in ('"', "'"):
                quote = ""  # a one-line string does not continue (the parser says why)
        elif quote:
            if quote in ('"', '"""') and ch == "\\":
                i += 1
                column += 1
            elif text.startswith(quote, i):
                i += len(quote) - 1
                column += len(quote) - 1
                quote = ""
        elif ch == "#":
            end = text.find("\n", i)
            i = n if end < 0 else end
            continue
        elif ch in "\"'":
            quote = ch * 3 if text.startswith(ch * 3, i) else ch
            i += len(quote) - 1
            column += len(quote) - 1
        elif ch in "[{":
            depth += 1
            if depth > MAX_CONFIG_NESTING:
                return line, column
        elif ch in "]}":
            depth = max(0, depth - 1)
        i += 1
    return None


def load_config(path: Path) -> CampaignConfig:
    """Read ``seqrun.toml``; :class:`ConfigInvalid` with ``file:line:col`` errors."""
    return read_config(path)[0]


def read_config(path: Path) -> tuple[CampaignConfig, bytes]:
    """``seqrun.toml`` and the bytes it was read from (a run folder keeps these);
    :class:`ConfigInvalid` with ``file:line:col`` errors."""
    shown = os.path.relpath(path) if path.is_absolute() else str(path)
    try:
        source = path.read_bytes()
        text = source.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = source.count(b"\n", 0, exc.start) + 1
        column = exc.start - (source.rfind(b"\n", 0, exc.start) + 1) + 1
        raise ConfigInvalid([SourceError(shown, line, column,
                                         f"not UTF-8 text ({exc.reason})")]) from None
    except OSError as exc:
        raise UserInputError(f"{shown}: {exc.strerror or exc}") from None
    deep = _too_deep(text)
    if deep is not None:
        raise ConfigInvalid([SourceError(shown, *deep, "invalid TOML: arrays or tables "
                                         f"nested more than {MAX_CONFIG_NESTING} deep")])
    import tomllib  # only where a seqrun.toml is read (it compiles its regexes at import)

    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        message = str(exc)
        match = re.search(r"\(at line (\d+), column (\d+)\)", message)
        line, column = (int(match.group(1)), int(match.group(2))) if match else (1, 1)
        message = re.sub(r"\s*\(at (line \d+, column \d+|end of document)\)", "", message)
        raise ConfigInvalid([SourceError(shown, line, column,
                                           f"invalid TOML: {message}")]) from None
    except RecursionError:  # nesting the scan above did not see (it skips strings)
        raise ConfigInvalid([SourceError(shown, 1, 1, "invalid TOML: nested too "
                                                      "deep")]) from None
    # the models only where a seqrun.toml is read (four pydantic models, built at import)
    from pydantic import ValidationError

    from seqrun.sequence.campaign_config import CampaignConfig

    try:
        return CampaignConfig.model_validate(data), source
    except ValidationError as exc:
        errors = []
        for error in exc.errors():
            line, column = _config_location(text, tuple(error["loc"]))
            where = ".".join(str(k) for k in error["loc"])
            message = ("unknown key (expected: " + _expected(error["loc"]) + ")"
                       if error["type"] == "extra_forbidden"
                       else error["msg"].removeprefix("Value error, "))
            errors.append(SourceError(shown, line, column,
                                      f"{where}: {message}" if where else message))
        raise ConfigInvalid(errors) from None


def _expected(loc: tuple) -> str:
    from pydantic import BaseModel

    from seqrun.sequence.campaign_config import CampaignConfig

    model: type[BaseModel] = CampaignConfig
    for key in loc[:-1]:
        field = model.model_fields.get(str(key))
        if field is None or not isinstance(field.annotation, type):
            break
        model = field.annotation
    return ", ".join(model.model_fields)


def find_campaign(start: Path) -> Path | None:
    """The nearest folder at or above ``start`` holding a ``seqrun.toml``."""
    start = start.resolve()
    for folder in (start if start.is_dir() else start.parent, *start.parents):
        if (folder / CONFIG_NAME).is_file():
            return folder
    return None


def _legacy_root(start: Path) -> Path:
    """Nearest ancestor holding an ``arms/`` or ``poses/`` folder; else the cwd."""
    start = start.resolve()
    for folder in (start if start.is_dir() else start.parent, *start.parents):
        if (folder / "arms").is_dir() or (folder / "poses").is_dir():
            return folder
    return Path.cwd().resolve()


@dataclass(frozen=True)
class Project:
    """The folder a sequence belongs to, and where its files are looked up."""

    root: Path
    config_path: Path | None = None
    config: CampaignConfig | None = None
    #: The bytes ``config`` was read from (a run folder keeps these, not the file again).
    config_source: bytes = field(default=b"", repr=False, compare=False)

    @property
    def is_campaign(self) -> bool:
        return self.config_path is not None

    @property
    def poses_dir(self) -> Path:
        return self.root / "poses"

    @property
    def pose_path(self) -> tuple[Path, ...]:
        """Where poses are looked up, first match wins: the project's, then the shipped."""
        own, shipped = self.poses_dir, shipped_dir("poses")
        if own.resolve() == shipped.resolve():
            return (own,)
        return (own, shipped)

    @property
    def runs_dir(self) -> Path:
        if self.config is not None:
            return self.root / self.config.runs.dir
        return Path("runs")

    def include_tree(self, top: Path) -> Path:
        """The folder includes of ``top`` must stay inside: the whole campaign; without
        one, the project's ``sequences/`` (or the folder of the file given)."""
        if self.is_campaign:
            return self.root
        sequences = self.root / "sequences"
        return sequences if top.is_relative_to(sequences) else top.parent

    def arm_candidates(self, name: str | None) -> list[Path]:
        """The files an arm reference may mean, in search order. ``name``: what a sequence's
        ``arm:`` says (a file relative to the project), else the campaign's arm."""
        if name is None and self.config is not None:
            name = self._default_arm()
        if name is None:
            return [self.root / "arms" / f"{DEFAULT_ARM_NAME}.yaml",
                    shipped_dir("arms") / f"{DEFAULT_ARM_NAME}.yaml"]
        if "/" not in name and "\\" not in name and not name.endswith((".yaml", ".yml")):
            return [self.root / "arms" / f"{name}.yaml", shipped_dir("arms") / f"{name}.yaml"]
        candidates = [self.root / name]
        shipped = shipped_arm(Path(name).stem)
        if name.startswith("arms/") and shipped is not None:
            candidates.append(shipped)  # 'arms/lwa3.yaml' of a sequence written for the checkout
        return candidates

    def arm_path(self, name: str | None = None) -> Path:
        """The arm file, or :class:`UserInputError` naming every place searched."""
        candidates = self.arm_candidates(name)
        for path in candidates:
            if path.is_file():
                return path.resolve()
        if name is None and self.config is not None:
            name = self._default_arm()
        what = f"arm '{name}'" if name else "the arm"
        raise UserInputError(f"{what} not found (looked for "
                             + ", ".join(str(p) for p in candidates) + ")")

    def _default_arm(self) -> str:
        """The campaign's arm; with several arms ([arms.ID]) the first one's (a sequence
        fragment that names no arm is checked against it)."""
        assert self.config is not None
        if self.config.arms:
            return next(iter(self.config.arms.values())).arm
        return self.config.campaign.arm

    def describe(self) -> str:
        if self.config_path is not None:
            return f"campaign {self.root}"
        return f"project {self.root} (no {CONFIG_NAME})"


def open_project(folder: Path) -> Project:
    """The project in ``folder`` (``--project DIR``)."""
    folder = Path(folder)
    if not folder.is_dir():
        raise UserInputError(f"project folder {folder} does not exist")
    config_path = folder / CONFIG_NAME
    if config_path.is_file():
        config, source = read_config(config_path)
        return Project(folder.resolve(), config_path.resolve(), config, source)
    return Project(folder.resolve())


def project_for(path: Path, project_dir: Path | None = None) -> Project:
    """The project of a sequence (or folder) ``path``: ``project_dir`` if given, else the
    nearest campaign above it, else the nearest folder with ``arms/`` or ``poses/``."""
    if project_dir is not None:
        return open_project(project_dir)
    campaign = find_campaign(path)
    if campaign is not None:
        return open_project(campaign)
    return Project(_legacy_root(path))

