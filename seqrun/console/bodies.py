"""Reading a request body or a live message: strict JSON, then a strict model.

The console parses JSON itself instead of letting the web framework do it, because the
framework's parser takes the last of two equal keys (``{"j1": 5, "j1": 60}`` is 60) and
accepts ``NaN``. Here a repeated key, ``NaN``/``Infinity``, a body that is not a JSON object
and a body over :data:`MAX_BODY_BYTES` are refused with one line (:class:`Malformed`), and the
model is validated in pydantic's strict mode (:mod:`seqrun.console.models`).
"""

from __future__ import annotations

import json
from typing import Any, TypeVar

from pydantic import BaseModel, ValidationError

#: The largest request body read (bytes). The API's bodies are a few hundred bytes.
MAX_BODY_BYTES = 64 * 1024
#: A body must have arrived within this time (s) of its request's head.
BODY_TIMEOUT_S = 10.0
#: Set in the ASGI scope by :class:`seqrun.console.limits.RequestLimits` when it stopped
#: reading a body: "too large" or "too slow".
BODY_CUT = "seqrun.body_cut"

Model = TypeVar("Model", bound=BaseModel)


class Malformed(Exception):
    """A request body or a live message that is not what the API takes (one line)."""

    def __init__(self, message: str, status: int = 422) -> None:
        super().__init__(message)
        self.status = status


def one_line(text: str) -> str:
    return " ".join(str(text).split())


def printable(text: str) -> str:
    """``text`` with control characters (escape sequences, NUL, BEL, line breaks) written
    as ``\\xNN``: what a request brings never reaches a terminal or a log raw."""
    return "".join(c if c.isprintable() else f"\\x{ord(c):02x}" if ord(c) < 256
                   else f"\\u{ord(c):04x}" for c in str(text))


def _no_repeated_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise Malformed(f"the key {json.dumps(key)[:60]} is given twice")
        out[key] = value
    return out


def _no_constant(name: str) -> Any:
    raise Malformed(f"{name} is not a finite number (JSON numbers only)")


def parse_json(raw: bytes | str) -> Any:
    """JSON without repeated keys or NaN/Infinity; :class:`Malformed` otherwise."""
    try:
        return json.loads(raw, object_pairs_hook=_no_repeated_keys, parse_constant=_no_constant)
    except Malformed:
        raise
    except (ValueError, UnicodeDecodeError) as exc:
        raise Malformed(f"not JSON: {exc}") from None


def validation_line(exc: ValidationError) -> str:
    """The first problem of a strict model's validation, as ``where: what``."""
    errors = exc.errors(include_url=False)
    if not errors:
        return "malformed"
    first = errors[0]
    where = ".".join(str(p) for p in first.get("loc", ()))
    what = first.get("msg", "invalid")
    if first.get("type") == "extra_forbidden":
        what = "unknown key"
    more = f" (and {len(errors) - 1} more)" if len(errors) > 1 else ""
    return one_line(f"{where + ': ' if where else ''}{what}{more}")


def to_model(data: Any, model: type[Model]) -> Model:
    if not isinstance(data, dict):
        raise Malformed("the request body must be a JSON object (Content-Type: "
                        "application/json)")
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        raise Malformed(validation_line(exc)) from None


def check_body(raw: bytes, content_type: str | None, cut: str | None) -> Any:
    """A request body as JSON (``None`` when empty). ``cut``: why the reading stopped
    early (:data:`BODY_CUT`)."""
    if cut == "too large":
        raise Malformed(f"the request body is over {MAX_BODY_BYTES} bytes", 413)
    if cut == "too slow":
        raise Malformed(f"the request body did not arrive within {BODY_TIMEOUT_S:g} s", 408)
    if not raw.strip():
        return None
    media = (content_type or "").split(";", 1)[0].strip().lower()
    if media != "application/json":
        raise Malformed("the request body must be a JSON object (Content-Type: "
                        f"application/json, not {media or 'none'!r})")
    return parse_json(raw)


async def read_model(request: Any, model: type[Model]) -> Model:
    """The request's body as ``model`` (an empty body: the model's defaults, if it has
    them); :class:`Malformed` otherwise."""
    raw = await request.body()
    data = check_body(raw, request.headers.get("content-type"),
                      request.scope.get(BODY_CUT))
    return to_model({} if data is None else data, model)
