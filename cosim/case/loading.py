"""Reading a case file: TOML, ``--set`` overrides, the schema, then the cross-field checks, all
before any computation (each failure a :class:`cosim.errors.CaseError`).
"""
from __future__ import annotations

import copy
import re
import tomllib
from pathlib import Path

from pydantic import ValidationError

from cosim.case.messages import dotted, schema_error
from cosim.case.schema import Case
from cosim.case.validation import check_consistency, check_sections
from cosim.errors import CaseError


def load_case(path, overrides=()):
    """Read, override and validate a case file; return ``(Case, resolved dict)``.

    ``overrides`` are ``"section.key=value"`` strings; ``value`` is parsed as a
    TOML value (``1e-3``, ``true``, ``[0, 0, -9.81]``) or else taken as a string.
    Relative file paths in the case are resolved against the case file's folder.
    """
    path = Path(path)
    if not path.is_file():
        raise CaseError(path, "<file>", str(path), "the case file must exist and be a readable TOML file")
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
    except UnicodeDecodeError as exc:
        raise CaseError(path, "<encoding>", f"byte {exc.object[exc.start:exc.start + 1]!r} at offset {exc.start}",
                        "a case file must be UTF-8 text (TOML)") from None
    except tomllib.TOMLDecodeError as exc:
        raise CaseError(path, "<syntax>", str(exc), "the file must be valid TOML") from None
    raw = apply_overrides(path, raw, overrides)
    check_sections(path, raw)
    try:
        case = Case.model_validate(raw)
    except ValidationError as exc:
        raise schema_error(path, exc) from None
    check_consistency(path, case)
    return case, case.model_dump()


def apply_overrides(path, raw, overrides):
    """Return a copy of ``raw`` with ``--set a.b.c=value`` overrides applied."""
    raw = copy.deepcopy(raw)
    for item in overrides:
        if "=" not in item:
            raise CaseError(path, item, item, "--set needs the form section.key=value")
        key, text = item.split("=", 1)
        try:
            value = tomllib.loads(f"v = {text}")["v"]
        except tomllib.TOMLDecodeError:
            value = text
        parts = override_path(path, key.strip(), text)
        node = raw
        for depth, part in enumerate(parts[:-1]):
            if isinstance(part, int):
                if not isinstance(node, list) or part >= len(node):
                    where = dotted(parts[:depth])
                    count = len(node) if isinstance(node, list) else 0
                    raise CaseError(path, key, text, f"'{where}' has {count} entries in the case file; "
                                                     f"index {part} is not one of them")
                node = node[part]
                continue
            nxt = node.get(part)
            if nxt is None:
                nxt = node.setdefault(part, [] if isinstance(parts[depth + 1], int) else {})
            if not isinstance(nxt, (dict, list)):
                raise CaseError(path, key, text, f"'{dotted(parts[:depth + 1])}' is a value, not a table")
            node = nxt
        if not isinstance(node, dict):
            raise CaseError(path, key, text, "--set names a key of a table: section.key or section.list[i].key")
        node[parts[-1]] = value
    return raw


def override_path(path, key, text):
    """``dem.materials[0].friction`` → ["dem", "materials", 0, "friction"]."""
    parts = []
    for piece in key.split("."):
        match = re.fullmatch(r"([A-Za-z_][A-Za-z0-9_]*)((?:\[\d+\])*)", piece)
        if match is None:
            raise CaseError(path, key, text, "--set needs section.key=value (a list entry: section.list[i].key=value)")
        parts.append(match.group(1))
        parts.extend(int(i) for i in re.findall(r"\[(\d+)\]", match.group(2)))
    if isinstance(parts[-1], int):
        raise CaseError(path, key, text, "--set replaces one key, not a whole list entry")
    return parts
