"""Typed parameters of a sequence: the ``params:`` block, its values and ``${name}``.

A sequence file may declare parameters::

    params:
      speed: {type: float, min: 0.1, max: 1.0, default: 0.5, description: Velocity scale}
      target: {type: pose, default: opsafe}
    steps:
      - move: {pose: ${target}, velocity_scale: ${speed}}

The values are the defaults, overridden by ``--param name=value``; each is checked against
its type (strictly: ``true`` is not an int, ``"12"`` not a number) and its min/max/choices.
:func:`substitute` puts them into a file's data before its steps are validated: a scalar
that is exactly ``${name}`` becomes the typed value, ``${name}`` inside a longer text is
replaced as text. Only the data changes (never its shape), so every location the YAML
nodes give stays right. Pure: no I/O.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Mapping
from typing import Any, ClassVar, Literal

from pydantic import Field, ValidationInfo, field_validator, model_validator
from pydantic_core import PydanticCustomError

from seqrun.errors import SourceError, UserInputError
from seqrun.steps.params import Finite, StrictModel

__all__ = ["NUMERIC", "ParameterSpec", "expression_types", "extremes", "parse_options",
           "parse_value", "references", "resolve_values", "show_value", "substitute"]

#: The parameter types, as written after ``type:``.
ParameterType = Literal["int", "float", "bool", "str", "choice", "pose"]
#: The types with a range (min/max) that ``seqrun validate`` checks at both ends.
NUMERIC = ("int", "float")
NAME_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
#: ``${name}`` in a text (a name as NAME_RE, or anything else up to '}' to say it is bad).
_REFERENCE_RE = re.compile(r"\$\{([^}]*)\}")


class ParameterSpec(StrictModel):
    """One parameter: its type, range and default."""

    yaml_name: ClassVar[str] = "a parameter"

    type: ParameterType = Field(description="int, float, bool, str, choice (one of "
                                            "'choices') or pose (a pose name).")
    unit: str | None = Field(None, min_length=1, description="Unit of the value (text, "
                                                             "e.g. mm), for people and "
                                                             "expressions.")
    min: Finite | None = Field(None, description="Smallest value (int and float).")
    max: Finite | None = Field(None, description="Largest value (int and float).")
    choices: list[str | int | float] | None = Field(
        None, min_length=1, description="The allowed values (type choice).")
    default: bool | int | float | str | None = Field(
        None, description="Value used when the command line gives none (--param "
                          "NAME=VALUE); without one the command line must give it.")
    description: str = Field("", description="What the parameter means.")

    @model_validator(mode="after")
    def _consistent(self) -> ParameterSpec:
        if (self.min is not None or self.max is not None) and self.type not in NUMERIC:
            raise PydanticCustomError("param_range", "min and max are for int and float "
                                                     "parameters")
        if self.min is not None and self.max is not None and self.min > self.max:
            raise PydanticCustomError("param_range", "min is greater than max")
        if (self.choices is None) != (self.type != "choice"):
            raise PydanticCustomError("param_choices", "a choice parameter lists its "
                                                       "'choices'; only a choice has them")
        return self

    @field_validator("default")
    @classmethod
    def _default_fits(cls, value: Any, info: ValidationInfo) -> Any:
        """The default is a value of the declared type and range (at the default's place:
        the fields before it are validated by then)."""
        if value is None or "type" not in info.data:
            return value
        spec = cls.model_construct(**{**info.data, "default": None})
        problem = value_problem(spec, value)
        if problem is not None:
            raise PydanticCustomError("param_default", "default: {problem}",
                                      {"problem": problem})
        return value


def show_value(value: Any) -> str:
    """A value as it is written in a file or on the command line."""
    if isinstance(value, bool):
        return "true" if value else "false"
    return repr(value) if isinstance(value, float) else str(value)


def value_problem(spec: ParameterSpec, value: Any) -> str | None:
    """Why ``value`` (typed, as from a file) is not a value of ``spec``; None if it is."""
    kind = spec.type
    if kind == "int" and type(value) is not int:
        return f"expected a whole number, got {_shown(value)}"
    if kind == "float" and (type(value) not in (int, float) or not math.isfinite(value)):
        return f"expected a finite number, got {_shown(value)}"
    if kind == "bool" and type(value) is not bool:
        return f"expected true or false, got {_shown(value)}"
    if kind in ("str", "pose") and (type(value) is not str or not value):
        return f"expected {'a pose name' if kind == 'pose' else 'text'}, got {_shown(value)}"
    if kind == "choice" and (type(value) is bool or value not in (spec.choices or [])):
        options = ", ".join(show_value(c) for c in spec.choices or [])
        return f"expected one of {options}, got {_shown(value)}"
    if kind not in NUMERIC:
        return None
    if spec.min is not None and value < spec.min:
        return f"{show_value(value)} is below the minimum {show_value(spec.min)}"
    if spec.max is not None and value > spec.max:
        return f"{show_value(value)} is above the maximum {show_value(spec.max)}"
    return None


def _shown(value: Any) -> str:
    return f"'{value}'" if isinstance(value, str) else show_value(value)


_INT_RE = re.compile(r"^[-+]?[0-9]+$")
_FLOAT_RE = re.compile(r"^[-+]?(?:\.[0-9]+|[0-9]+(?:\.[0-9]*)?)(?:[eE][-+]?[0-9]+)?$")


def parse_value(spec: ParameterSpec, text: str) -> Any:
    """The typed value of a command-line text; raises ValueError saying why not."""
    kind = spec.type
    value: Any = text
    if not text.isprintable():  # it would reach the operator's terminal and the report
        raise ValueError("a value is printable text (no control characters)")
    if kind == "int":
        if not _INT_RE.match(text):
            raise ValueError(f"expected a whole number, got '{text}'")
        value = int(text)
    elif kind == "float":
        if not _FLOAT_RE.match(text):
            raise ValueError(f"expected a number, got '{text}'")
        value = float(text)
    elif kind == "bool":
        if text not in ("true", "false"):
            raise ValueError(f"expected true or false, got '{text}'")
        value = text == "true"
    elif kind == "choice":  # a choice as written (numbers compared as numbers)
        for choice in spec.choices or []:
            if show_value(choice) == text or (not isinstance(choice, str)
                                              and _FLOAT_RE.match(text)
                                              and float(text) == choice):
                return choice
    problem = value_problem(spec, value)
    if problem is not None:
        raise ValueError(problem)
    return value


def parse_options(options: Iterable[str]) -> dict[str, str]:
    """``--param NAME=VALUE`` options as ``{name: text}``; UserInputError for a bad one."""
    result: dict[str, str] = {}
    for option in options:
        name, sep, text = option.partition("=")
        name = name.strip()
        if not sep or not NAME_RE.match(name):
            raise UserInputError(f"--param '{option}': expected NAME=VALUE, e.g. "
                                 "--param speed=0.5")
        if name in result:
            raise UserInputError(f"--param {name} is given twice")
        result[name] = text
    return result


def resolve_values(specs: Mapping[str, ParameterSpec], given: Mapping[str, str], *,
                   file: str) -> dict[str, Any]:
    """The value of every parameter: ``given`` (command-line texts) over the defaults.
    Raises UserInputError (one line) for an unknown name, a bad value or a missing one."""
    for name in given:
        if name not in specs:
            declared = ", ".join(specs) or "none"
            raise UserInputError(f"--param {name}: {file} declares no parameter '{name}' "
                                 f"(declared: {declared})")
    values: dict[str, Any] = {}
    for name, spec in specs.items():
        if name in given:
            try:
                values[name] = parse_value(spec, given[name])
            except ValueError as exc:
                shown = given[name] if given[name].isprintable() else ascii(given[name])
                raise UserInputError(f"--param {name}={shown}: {exc}") from None
        elif spec.default is not None:
            values[name] = float(spec.default) if spec.type == "float" else spec.default
        else:
            raise UserInputError(f"{file}: parameter '{name}' has no default: give its value "
                                 f"with --param {name}=VALUE")
    return values


def extremes(specs: Mapping[str, ParameterSpec]) -> list[tuple[str, Any, str]]:
    """``(name, value, "min" | "max")`` of every end of a numeric range, in order."""
    ends = []
    for name, spec in specs.items():
        if spec.type in NUMERIC:
            for end in ("min", "max"):
                value = getattr(spec, end)
                if value is not None and value != spec.default:
                    ends.append((name, int(value) if spec.type == "int" else float(value), end))
    return ends


def expression_types(specs: Mapping[str, ParameterSpec]) -> dict[str, tuple[str, str | None]]:
    """The parameters an expression may read as ``params.NAME``: numbers and truth values
    (name -> (expression type, unit))."""
    kinds = {"int": "number", "float": "number", "bool": "bool"}
    return {name: (kinds[spec.type], spec.unit) for name, spec in specs.items()
            if spec.type in kinds}


def references(text: str) -> list[tuple[int, str]]:
    """Every ``${name}`` in ``text``: (offset of the '$', name)."""
    return [(m.start(), m.group(1)) for m in _REFERENCE_RE.finditer(text)]


def substitute(data: Any, values: Mapping[str, Any], declared: Iterable[str],
               locate: Any, path: tuple = ()) -> tuple[Any, list[SourceError]]:
    """``data`` with every ``${name}`` replaced (a copy; its shape unchanged), and an error
    for each reference to a name not declared. ``locate(path, offset)`` gives the
    SourceError maker (a Location) of the text at ``path``, ``offset`` characters in.
    A declared parameter without a value (its declaration has errors) is left as written."""
    errors: list[SourceError] = []
    known = set(declared)

    def walk(value: Any, where: tuple) -> Any:
        if isinstance(value, dict):
            return {k: walk(v, where + (k,)) for k, v in value.items()}
        if isinstance(value, list):
            return [walk(v, where + (i,)) for i, v in enumerate(value)]
        if not isinstance(value, str) or "${" not in value:
            return value
        found = references(value)
        for offset, name in found:
            if name not in known:
                hint = f" (declared: {', '.join(sorted(known))})" if known else \
                    " (declare it under params:)"
                errors.append(locate(where, offset).error(
                    f"unknown parameter '${{{name}}}'{hint}"))
        if len(found) == 1 and found[0][0] == 0 and value == f"${{{found[0][1]}}}":
            name = found[0][1]
            return values.get(name, value)

        def text_of(match: re.Match[str]) -> str:
            name = match.group(1)
            return show_value(values[name]) if name in values else match.group(0)
        return _REFERENCE_RE.sub(text_of, value)

    return walk(data, path), errors
