"""The files a case names: relative to the case file's folder, a mesh also from the project's
``meshes/`` folder."""
from __future__ import annotations

from pathlib import Path


def resolve_path(case_file, relative):
    """A path in a case file, relative to the case file's folder."""
    p = Path(relative)
    return p if p.is_absolute() else (Path(case_file).parent / p).resolve()


def mesh_path(case_file, name):
    """A mesh named in a case: relative to the case file, else in the project's meshes/ folder."""
    local = resolve_path(case_file, name)
    if local.exists():
        return local
    return Path(__file__).resolve().parents[2] / "meshes" / name
