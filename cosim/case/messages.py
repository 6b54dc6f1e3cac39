"""The messages of a refused case: a pydantic error turned into one line naming the file, the
dotted key, the value and what is allowed; and the warning for a legal but suspicious value.
"""
from __future__ import annotations

import sys

from pydantic import BaseModel

from cosim.case.schema import Case
from cosim.errors import CaseError


def dotted(loc):
    """A key's path as the case file writes it: ``["dem", "materials", 0, "friction"]`` →
    ``dem.materials[0].friction``."""
    out = ""
    for part in loc:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out


def schema_error(path, exc, root=None):
    """The first pydantic error of a file validated against ``root`` (default :class:`Case`)
    as a CaseError naming the dotted key, the value and what is allowed."""
    root = root or Case
    err = exc.errors()[0]
    loc = [p for p in err["loc"] if not (isinstance(p, str) and ("[" in p or p.startswith("function-")))]
    key = dotted(loc)
    msg = err["msg"]
    if err["type"] == "extra_forbidden":
        parent = model_at(loc[:-1], root)
        allowed = ", ".join(parent.model_fields) if parent else "see `cosim schema`"
        return CaseError(path, key, err.get("input"), f"unknown key; allowed keys here: {allowed}")
    if err["type"] == "missing":
        return CaseError(path, key, None, "required key is missing")
    field = field_at(loc, root)
    desc = f" ({field.description})" if field is not None and field.description else ""
    return CaseError(path, key, err.get("input"), msg + desc)


def model_at(loc, root):
    model = root
    for part in loc:
        if isinstance(part, int):
            continue
        field = model.model_fields.get(part)
        if field is None:
            return None
        model = inner_model(field.annotation)
        if model is None:
            return None
    return model


def field_at(loc, root):
    parent = model_at(loc[:-1], root)
    names = [p for p in loc if isinstance(p, str)]
    if parent is None or not names:
        return None
    return parent.model_fields.get(names[-1])


def inner_model(annotation):
    """The BaseModel inside Optional[...] / list[...], if any."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    for arg in getattr(annotation, "__args__", ()):
        inner = inner_model(arg)
        if inner is not None:
            return inner
    return None


def warn(file, key, value, text):
    """A legal but suspicious value: one line on rank 0, the run goes on."""
    from cosim.outputs import say
    say(f"cosim: warning: {file}: key '{key}' = {value!r}: {text}", file=sys.stderr)
