"""PLACEHOLDER (to be replaced by the sequence-language work): YAML -> pydantic with file:line:col."""

from __future__ import annotations

from pathlib import Path

import yaml
from pydantic import BaseModel, ValidationError

from seqrun.errors import SequenceInvalid, SourceError


def load_model(path: Path, model: type[BaseModel]):
    text = Path(path).read_text(encoding="utf-8")
    data = yaml.safe_load(text)
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        raise SequenceInvalid([SourceError(str(path), 1, 1, e["msg"]) for e in exc.errors()])
