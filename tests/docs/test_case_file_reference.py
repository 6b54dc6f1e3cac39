"""The committed case-file reference (docs/reference/case-file.md) is the schema's.

The page is generated from the pydantic models of cosim/case.py by cosim/schema_doc.py
(`make docs-reference`); `make docs` only builds it, so a schema change without a
regenerated page fails here, not silently in the manual.
"""
import difflib

from cosim.schema_doc import PAGE, all_keys, render_markdown


def test_committed_page_is_up_to_date():
    committed = PAGE.read_text(encoding="utf-8")
    fresh = render_markdown()
    if committed != fresh:
        diff = "".join(list(difflib.unified_diff(committed.splitlines(True), fresh.splitlines(True),
                                                 "docs/reference/case-file.md", "from the schema", n=0))[:40])
        raise AssertionError(f"{PAGE} is out of date with cosim/case.py: run `make docs-reference` "
                             f"and commit the page.\n{diff}")


def test_every_schema_key_is_on_the_page():
    page = PAGE.read_text(encoding="utf-8")
    missing = [k for k in all_keys() if f"`{k}`" not in page and f"`[{k}]`" not in page and f"`[[{k}]]`" not in page]
    assert not missing, f"keys of the schema missing from {PAGE} (run `make docs-reference`): {missing}"
