"""The case-file schema as a list of keys, and as the manual's reference page.

:func:`walk` visits every key of the pydantic models in :mod:`cosim.case.schema` (tables and
their keys, depth first, in declaration order). ``cosim schema`` prints it as text;
:func:`render_markdown` renders it as docs/reference/case-file.md, one table per TOML
table with a row per key (type, unit, default, allowed values, meaning). Regenerate the
page after changing the schema::

    make docs-reference        # = python -m cosim.schema_doc docs/reference/case-file.md

tests/docs/test_case_file_reference.py fails while the committed page differs.
"""
from __future__ import annotations

import re
import sys
import types
import typing
from dataclasses import dataclass
from pathlib import Path

import annotated_types as at
from pydantic import BaseModel
from pydantic.fields import FieldInfo

from cosim.case.calibration import CalibrationFile
from cosim.case.messages import inner_model
from cosim.case.schema import SECTIONS_OF_KIND, Case

PAGE = Path(__file__).resolve().parents[1] / "docs" / "reference" / "case-file.md"


@dataclass(frozen=True)
class Entry:
    """One key of the schema: a table (``model`` set) or a value (``model`` None)."""
    key: str                 # dotted path, e.g. "dem.materials.density"
    field: FieldInfo
    model: type[BaseModel] | None = None
    is_list: bool = False    # a list of tables, [[key]]

    @property
    def parent(self):
        return self.key.rpartition(".")[0]


def walk(model=Case, prefix=""):
    """Every key of ``model`` and of the tables inside it, depth first, as :class:`Entry`."""
    for name, field in model.model_fields.items():
        inner = inner_model(field.annotation)
        key = f"{prefix}{name}"
        if inner is not None:
            yield Entry(key, field, inner, "list" in str(field.annotation))
            yield from walk(inner, key + ".")
        else:
            yield Entry(key, field)


def default_value(field):
    """The default as Python gives it (a default_factory called); ``...`` when required."""
    if field.is_required():
        return ...
    return field.get_default(call_default_factory=True)


# --------------------------------------------------------------------------- types, units, bounds
_UNITS = ("-", "m", "s", "Pa", "kg/m^3", "m/s", "m/s^2", "1/s", "N", "J", "rad", "deg")
_UNIT_RE = re.compile(r"\[(" + "|".join(re.escape(u) for u in _UNITS) + r")\]")


def _strip_optional(annotation):
    if typing.get_origin(annotation) in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(annotation) if a is not type(None)]
        if len(args) == 1:
            return args[0]
    return annotation


def _split_annotated(annotation):
    """(type, constraint metadata) of ``Annotated[T, Field(...)]`` or of a plain type."""
    if typing.get_origin(annotation) is typing.Annotated:
        base, *extras = typing.get_args(annotation)
        meta = []
        for extra in extras:
            meta.extend(extra.metadata if isinstance(extra, FieldInfo) else [extra])
        return base, meta
    return annotation, []


def _length(meta):
    lo = next((m.min_length for m in meta if isinstance(m, at.MinLen)), None)
    hi = next((m.max_length for m in meta if isinstance(m, at.MaxLen)), None)
    return lo, hi


_NAMES = {str: "string", int: "integer", float: "float", bool: "boolean"}


def toml_type(annotation, meta=()):
    """The TOML type of a value annotation, e.g. ``array of 3 floats``."""
    annotation, inner_meta = _split_annotated(_strip_optional(annotation))
    origin = typing.get_origin(annotation)
    if origin is typing.Literal:
        return "integer" if all(isinstance(a, int) for a in typing.get_args(annotation)) else "string"
    if origin is list:
        (item,) = typing.get_args(annotation)
        lo, hi = _length(list(meta) + inner_meta)
        item_type = toml_type(item)
        if lo is not None and lo == hi:
            return f"array of {lo} {_plural(item_type)}"
        return f"array of {_plural(item_type)}"
    if origin is dict:
        return f"table of {_plural(toml_type(typing.get_args(annotation)[1]))}"
    return _NAMES.get(annotation, getattr(annotation, "__name__", str(annotation)))


def _plural(type_name):
    first, _, rest = type_name.partition(" ")
    return f"{first}s {rest}".rstrip()


def _items(n):
    return f"{n} item" if n == 1 else f"{n} items"


def _bounds(meta):
    parts = []
    for m in meta:
        for cls, attr, sign in ((at.Gt, "gt", ">"), (at.Ge, "ge", "≥"), (at.Lt, "lt", "<"), (at.Le, "le", "≤")):
            if isinstance(m, cls):
                parts.append(f"{sign} {_number(getattr(m, attr))}")
    return parts


def allowed(field):
    """Allowed values and bounds of a value key, as short phrases."""
    annotation, inner_meta = _split_annotated(_strip_optional(field.annotation))
    meta = list(field.metadata)
    parts = []
    if typing.get_origin(annotation) is typing.Literal:
        parts.append(", ".join(f"`{toml_value(a)}`" for a in typing.get_args(annotation)))
    if _bounds(meta + inner_meta):
        parts.append(", ".join(_bounds(meta + inner_meta)))
    if typing.get_origin(annotation) is list:
        lo, hi = _length(meta)
        if lo is not None and lo != hi:
            parts.append(f"{lo} to {_items(hi)}" if hi is not None else f"at least {_items(lo)}")
        elif lo is None and hi is not None:
            parts.append(f"at most {_items(hi)}")
        item, item_meta = _split_annotated(typing.get_args(annotation)[0])
        if typing.get_origin(item) is not list:  # a list of lists: the length is in the type already
            item_bounds = _bounds(item_meta)
            if item_bounds:
                parts.append("each item " + ", ".join(item_bounds))
    for m in meta:
        pattern = getattr(m, "pattern", None)
        if pattern:
            parts.append(f"matches `{pattern}`")
    return "; ".join(parts)


def unit(description):
    """The units named in a description (``[m]``, ``[Pa]``, ``[-]``...), ``" or "``-joined."""
    found = []
    for u in _UNIT_RE.findall(description or ""):
        if u not in found:
            found.append(u)
    return " or ".join(found)


def _number(x):
    if isinstance(x, float) and x != 0 and (abs(x) >= 1e5 or abs(x) < 1e-3):
        mantissa, _, exponent = f"{x:g}".partition("e")
        return f"{mantissa}e{int(exponent)}" if exponent else mantissa
    return repr(x)


def toml_value(value):
    """A Python default written as TOML (``"linear"``, ``true``, ``[0.0, 0.0, -9.81]``)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, float) and (value == 0 or 1e-4 <= abs(value) < 1e6):
        return repr(value)
    if isinstance(value, (int, float)):
        return _number(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k} = {toml_value(v)}" for k, v in value.items()) + "}"
    return repr(value)


# --------------------------------------------------------------------------- markdown
def _text(s):
    """Markdown-escape plain text, leaving `code spans` as they are."""
    pieces = re.split(r"(`[^`]*`)", s)
    for i in range(0, len(pieces), 2):
        pieces[i] = re.sub(r"([\\*_<>$])", r"\\\1", pieces[i])
    return "".join(pieces)


def _cell(s):
    return s.replace("|", "\\|").replace("\n", " ")


def _meaning(description):
    """The description without a trailing unit when it names only that one (it has its own column)."""
    d = (description or "").strip()
    m = re.search(r"\s*" + _UNIT_RE.pattern + r"$", d)
    return d[:m.start()] if m and len(_UNIT_RE.findall(d)) == 1 else d


def _table_rows(entries):
    rows = ["| Key | Type | Unit | Default | Allowed | Meaning |",
            "|-----|------|------|---------|---------|---------|"]
    for e in entries:
        default = default_value(e.field)
        default = "required" if default is ... else ("not set" if default is None else f"`{toml_value(default)}`")
        cells = [f"`{e.key}`", toml_type(e.field.annotation, e.field.metadata), unit(e.field.description),
                 default, allowed(e.field), _text(_meaning(e.field.description))]
        rows.append("| " + " | ".join(_cell(c) for c in cells) + " |")
    return rows


def _header(entry):
    return f"[[{entry.key}]]" if entry.is_list else f"[{entry.key}]"


def _section(entry, leaves, level, top=False):
    lines = [f"{'#' * level} `{_header(entry)}`", ""]
    what = []
    description = (entry.field.description or "").strip().rstrip(".")
    if description.startswith(_header(entry)):  # "[[dem.walls]] tables", "[fe.damping] for quasi-static runs"
        description = description[len(_header(entry)):].lstrip(": ")
        description = "" if description == "tables" else description
    if description:
        what.append(_text(description[0].upper() + description[1:]) + ".")
    if entry.is_list:
        lo, hi = _length(entry.field.metadata)
        count = (f"{lo} to {hi}" if lo is not None and hi is not None else
                 f"at least {lo}" if lo is not None else f"at most {hi}" if hi is not None else "any number")
        what.append(f"A list of tables: one `{_header(entry)}` per entry, {count}.")
    elif entry.field.is_required():
        what.append("Required.")
    elif top and entry.field.default_factory is not None:
        what.append("Optional: every key has a default.")
    else:
        what.append("Optional.")
    if top:
        kinds = [k for k, sections in SECTIONS_OF_KIND.items() if entry.key in sections]
        what.append("Used by the kinds: " + ", ".join(f"`{k}`" for k in kinds) + ".")
    lines += [" ".join(what), ""]
    if leaves:
        lines += _table_rows(leaves) + [""]
    return lines


def _tables(model):
    """(table entry or None for the root, its value entries) in walk order."""
    tables = [None]
    leaves = {"": []}
    for e in walk(model):
        if e.model is not None:
            tables.append(e)
            leaves[e.key] = []
        else:
            leaves[e.parent].append(e)
    return [(t, leaves["" if t is None else t.key]) for t in tables]


def render_markdown():
    """docs/reference/case-file.md, as a string."""
    out = [
        "# Case-file reference",
        "",
        "<!-- Generated from the pydantic models in cosim/case/schema.py by `make docs-reference`",
        "     (cosim/schema_doc.py); do not edit by hand. -->",
        "",
        "Every key a case file may hold, table by table, from the schema that validates it "
        "(`cosim/case/schema.py`); `cosim schema` prints the same list in a terminal. A key not listed "
        "here is an error, as is a value of another type (TOML types are strict: `1` is not a "
        "string, `\"yes\"` not a boolean; a float key accepts an integer) or outside the bounds "
        "given. *Unit* `-` means dimensionless; *not set* means the key is optional and the "
        "meaning says what happens without it. How to write and check a case file: "
        "[Case files](../case-files.md).",
        "",
        "## Sections by kind",
        "",
        "`case.kind` chooses the run; each kind uses the sections below, and refuses the others.",
        "",
        "| Kind | Sections |",
        "|------|----------|",
    ]
    for kind, sections in SECTIONS_OF_KIND.items():
        out.append(f"| `{kind}` | " + ", ".join(f"[`[{s}]`](#{s})" for s in sections) + " |")
    out.append("")
    for table, leaves in _tables(Case):
        if table is None:
            continue
        top = "." not in table.key
        out += _section(table, leaves, 2 if top else 3, top=top)
    out += [
        "## Calibration files",
        "",
        "The file `cosim calibrate` reads (a TOML file of its own, not a case file): the targets "
        "to reach, the micro-parameters to vary within bounds, and the case it runs.",
        "",
    ]
    for table, leaves in _tables(CalibrationFile):
        if table is None:
            out += ["### Top level", "", "Keys outside any table.", ""] + _table_rows(leaves) + [""]
        else:
            out += _section(table, leaves, 3)
    return "\n".join(out).rstrip("\n") + "\n"


def all_keys():
    """Every dotted key of case files and calibration files, tables included."""
    return [e.key for e in walk(Case)] + [e.key for e in walk(CalibrationFile)]


def main(argv=None):
    """``python -m cosim.schema_doc [PATH]``: write the page (default docs/reference/case-file.md)."""
    argv = sys.argv[1:] if argv is None else argv
    path = Path(argv[0]) if argv else PAGE
    text = render_markdown()
    if path.exists() and path.read_text(encoding="utf-8") == text:
        print(f"{path}: up to date")
    else:
        path.write_text(text, encoding="utf-8")
        print(f"{path}: written")
    return 0


if __name__ == "__main__":
    sys.exit(main())
