"""The case files the README and the manual show are the shipped ones: each loads to the same
validated case as its file in runs/ (relative paths resolved from runs/), so they cannot drift."""
import re
from pathlib import Path

import pytest

from cosim.case import load_case

ROOT = Path(__file__).parents[2]
SHOWN = [  # page, the runs/ file its first TOML block stands for, keys the page leaves out on purpose
    ("README.md", "runs/footing_small.toml", {("output", "progress_interval")}),
    ("docs/case-files.md", "runs/coupled_footing_on_sand.toml", set()),
]


def _first_toml_block(page):
    match = re.search(r"```toml\n(.*?)```", (ROOT / page).read_text(encoding="utf-8"), re.S)
    assert match, f"{page} shows no TOML case"
    return match.group(1)


def _without(resolved, keys):
    out = {section: dict(values) if isinstance(values, dict) else values for section, values in resolved.items()}
    for section, key in keys:
        out[section].pop(key, None)
    return out


@pytest.mark.parametrize("page, shipped, left_out", SHOWN, ids=[page for page, _, _ in SHOWN])
def test_a_case_shown_in_the_docs_is_the_shipped_case(page, shipped, left_out, tmp_path):
    shown = ROOT / Path(shipped).parent / f".shown_{tmp_path.name}.toml"  # beside it: same relative paths
    try:
        shown.write_text(_first_toml_block(page), encoding="utf-8")
        _, shown_case = load_case(shown)
    finally:
        shown.unlink(missing_ok=True)
    _, shipped_case = load_case(ROOT / shipped)
    assert _without(shown_case, left_out) == _without(shipped_case, left_out), \
        f"the case shown in {page} no longer matches {shipped}: update the page"
