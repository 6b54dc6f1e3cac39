"""What a gmsh model declares, read from its text without gmsh: the physical groups of a ``.geo``
source or ``.msh`` file and the ranges of a ``.geo``'s ``DefineConstant`` parameters. Fast enough
for ``cosim check`` to name a missing group or an out-of-range parameter before anything is
meshed (:mod:`fe_domain.mesh` builds the mesh itself)."""
from __future__ import annotations

import re
from pathlib import Path


def physical_groups(mesh_file):
    """``{name: dim}`` of the physical groups a .geo source or .msh file declares (text scan, no meshing)."""
    text = Path(mesh_file).read_text(errors="replace")
    if Path(mesh_file).suffix == ".geo":
        dims = {"Point": 0, "Curve": 1, "Line": 1, "Surface": 2, "Volume": 3}
        physical = r'Physical\s+(Point|Curve|Line|Surface|Volume)\s*\(\s*"([^"]+)"'
        return {m.group(2): dims[m.group(1)] for m in re.finditer(physical, text)}
    block = re.search(r"\$PhysicalNames\s*\n\s*\d+\s*\n(.*?)\$EndPhysicalNames", text, re.S)
    if block is None:
        return {}
    return {m.group(3): int(m.group(1)) for m in re.finditer(r'(\d+)\s+(\d+)\s+"([^"]+)"', block.group(1))}


_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"


def parameter_ranges(geo_file):
    """``{name: (min, max)}`` of the ``DefineConstant`` parameters of a .geo source: the range
    its ``Min`` and ``Max`` attributes declare (None where one is not declared)."""
    text = Path(geo_file).read_text(errors="replace")
    starts = [m.end() for m in re.finditer(r"\w+\s*=\s*\{", text)] + [len(text)]  # "name = {" of each entry
    ranges = {}
    for entry in re.finditer(r'Name\s+"Parameters/([^"]+)"', text):
        start = max((k for k in starts if k <= entry.start()), default=0)
        end = min((k for k in starts if k > entry.end()), default=len(text))
        attributes = text[start:end].split("]", 1)[0]  # to the next entry or the end of DefineConstant[...]
        bounds = [re.search(rf"\b{bound}\s+({_NUMBER})", attributes) for bound in ("Min", "Max")]
        ranges[entry.group(1)] = tuple(float(b.group(1)) if b else None for b in bounds)
    return ranges


