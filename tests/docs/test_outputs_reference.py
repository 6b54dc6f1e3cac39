"""docs/reference/outputs.md lists every CSV column the code writes, with a unit.

The column lists come from the code (the apps' ``COLUMNS``/``SERIES_COLUMNS`` constants,
``Engine.energy()`` of a two-sphere engine, and the CSV writers of ``cosim series``,
``cosim calibrate`` and the footing comparison); the page's tables are parsed. Each column
must appear in the first cell of a row of its file's table (the table under the ``###``
heading that names the file, within the ``##`` section of its kind), and that row's unit
cell must be filled ("–" for a dimensionless number). Also: the summary keys of the two lab
tests' ``summarize`` functions appear on the page. No simulation runs.
"""
from __future__ import annotations

import ast
import inspect
import re
from pathlib import Path

import numpy as np
import pytest

PAGE = Path(__file__).resolve().parents[2] / "docs" / "reference" / "outputs.md"


def _cells(line):
    return [c.strip() for c in re.split(r"(?<!\\)\|", line.strip())[1:-1]]


def tables(text):
    """{(kind heading, file heading): {column: unit}} of every ``###`` section's table."""
    out, kind, section = {}, None, None
    for line in text.splitlines():
        if line.startswith("## "):
            kind, section = line[3:].strip(), None
        elif line.startswith("### "):
            section = line[4:].strip()
            out.setdefault((kind, section), {})
        elif section is not None and line.startswith("|"):
            cells = _cells(line)
            if len(cells) < 2 or set(cells[0]) <= set("-: ") or cells[0] in ("column", "key"):
                continue  # the header and its rule
            for name in re.findall(r"`([^`]+)`", cells[0]):
                out[(kind, section)][name] = cells[1]
    return out


@pytest.fixture(scope="module")
def page():
    text = PAGE.read_text(encoding="utf-8")
    return text, tables(text)


def _table(found, kind, file):
    matches = [cols for (k, s), cols in found.items() if k == kind and f"`{file}`" in s]
    assert len(matches) == 1, f"docs/reference/outputs.md: no single table for {file} under '## {kind}'"
    return matches[0]


def _check(found, kind, file, columns):
    table = _table(found, kind, file)
    missing = [c for c in columns if c not in table]
    assert not missing, f"docs/reference/outputs.md, '## {kind}', {file}: columns not listed: {missing}"
    no_unit = [c for c in columns if not table[c]]
    assert not no_unit, f"docs/reference/outputs.md, '## {kind}', {file}: no unit for {no_unit} ('–' if none)"


def dem_energy_columns():
    """The terms of ``Engine.energy()``, from a two-sphere engine (no step is taken)."""
    from de_domain import Engine, Material, Particles
    materials = [Material()]
    particles = Particles.from_spheres(np.array([[0.0, 0.0, 0.0], [0.01, 0.0, 0.0]]), np.array([1e-3, 1e-3]),
                                       np.zeros(2, np.int32), materials)
    return list(Engine(particles, materials).energy())


def _dict_keys_appended(function, target):
    """Keys of the dict literal(s) passed to ``<target>.append({...})`` in ``function``'s source."""
    tree = ast.parse(inspect.getsource(function))
    keys = []
    for node in ast.walk(tree):
        if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "append"
                and isinstance(node.func.value, ast.Name) and node.func.value.id == target
                and node.args and isinstance(node.args[0], ast.Dict)):
            keys += [k.value for k in node.args[0].keys if isinstance(k, ast.Constant)]
    return keys


def _csv_header_literal(function, name="lines"):
    """The header of a CSV assembled as ``name = ["a,b,c", ...]`` in ``function``."""
    tree = ast.parse(inspect.getsource(function))
    for node in ast.walk(tree):
        if (isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == name for t in node.targets)
                and isinstance(node.value, ast.List) and node.value.elts
                and isinstance(node.value.elts[0], ast.Constant)):
            return node.value.elts[0].value.split(",")
    raise AssertionError(f"no CSV header literal in {function.__name__}")


def test_dem_series(page):
    from cosim.apps import dem
    _check(page[1], "DEM", "series.csv", [*dem.SERIES_COLUMNS, *dem_energy_columns()])


def test_fe_series_and_energies(page):
    from cosim.apps import fe
    from fe_domain.output import ENERGY_COLUMNS
    _check(page[1], "FE", "series.csv", [*fe.SERIES_COLUMNS, *fe.reaction_columns(["<group>"])])
    _check(page[1], "FE", "energies.csv", ENERGY_COLUMNS)


def test_coupled_series(page):
    from cosim.apps import coupled
    _check(page[1], "Coupled", "series.csv", coupled.COLUMNS)


def test_lab_series(page):
    from cosim.apps import direct_shear, triaxial
    _check(page[1], "Direct shear", "series.csv", direct_shear.COLUMNS)
    _check(page[1], "Triaxial", "series.csv", triaxial.COLUMNS)


def test_footing_csvs(page):
    from cosim import soil_model
    from cosim.apps import footing
    _check(page[1], "Footing", "load_settlement.csv", footing.COLUMNS)
    _check(page[1], "Footing", "rest.csv", soil_model.REST_COLUMNS)
    _check(page[1], "Footing", "comparison.csv", _csv_header_literal(footing.compare_models))


def test_series_and_calibrate_csvs(page, tmp_path):
    from cosim.lab import calibrate, series
    columns = _dict_keys_appended(series.run_series, "rows")
    assert "phi_deg" in columns  # the parse found the row dict
    _check(page[1], "cosim series", "mohr_coulomb.csv", columns)
    log = calibrate.EvaluationLog(tmp_path / "evaluations.csv", [], [])  # the fixed columns
    _check(page[1], "cosim calibrate", "evaluations.csv", [*log.columns, "<parameter>", "<quantity>@<σ>kPa"])


def test_lab_summary_keys(page):
    """The keys the two lab tests' ``summarize`` compute, from made-up curves."""
    from cosim.apps import triaxial
    from cosim.lab.shear_report import summarize
    text = page[0]
    x = np.linspace(0.0, 1.0, 11)
    shear = summarize(x * 9e-3, 50e3 * (1.0 + x), 100e3 * np.ones_like(x), 1e-4 * x)
    tri = triaxial.summarize({"axial_strain": x / 4, "sigma_1": 1e5 * (2.0 + x), "sigma_3": 1e5 * np.ones_like(x),
                              "volumetric_strain": -x / 100})
    missing = [k for k in [*shear, *tri] if f"`{k}`" not in text]
    assert not missing, f"docs/reference/outputs.md: summary keys not listed: {missing}"
