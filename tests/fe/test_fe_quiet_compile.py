"""A first run shows one short line while the FE kernels compile, never the compiler's commands.

A tiny solid is built in a subprocess with an empty private DOLFINx JIT cache
(dolfinx.jit reads ``$XDG_CACHE_HOME`` at import: the cache is
``$XDG_CACHE_HOME/fenics``), so every element, form and expression is compiled
(about 5 s), then again with that cache filled (nothing compiled, no line).
"""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from fe_domain.jit import MESSAGE, VERBOSE_ENV

REPO = Path(__file__).resolve().parents[2]

TINY_BUILD = """
from mpi4py import MPI
from fe_domain.build import build_solid
from fe_domain.output import FieldWriter
solid = build_solid("block.geo", 1.0, comm=MPI.COMM_SELF, material={"E": 1e7, "nu": 0.3, "rho": 1800.0},
                    boundary_conditions=[{"type": "fixed", "boundary": "bottom"}],
                    loads=[{"type": "pressure", "boundary": "top", "pressure": 1e3}])
solid.run(2)
writer = FieldWriter(solid, "fields")
writer.write()
writer.close()
print("built", flush=True)
"""


def _run(tmp_path):
    # setuptools' distutils (the default, "local") is the one that logged the commands.
    env = {k: v for k, v in os.environ.items() if k not in (VERBOSE_ENV, "SETUPTOOLS_USE_DISTUTILS")}
    # Private cache and config dirs: no ~/.config/dolfinx/dolfinx_jit_parameters.json may move the cache.
    env.update(XDG_CACHE_HOME=str(tmp_path / "cache"), XDG_CONFIG_HOME=str(tmp_path / "config"))
    work = tmp_path / "work"                # cwd: no ./dolfinx_jit_parameters.json either
    work.mkdir(exist_ok=True)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    proc = subprocess.run([sys.executable, "-c", TINY_BUILD], cwd=work, env=env, capture_output=True,
                          text=True, timeout=300)
    output = proc.stdout + proc.stderr
    assert proc.returncode == 0, output
    assert "built" in proc.stdout, output
    return proc, output


@pytest.mark.slow  # an FFCx build in an empty cache (~9 s)
def test_first_build_prints_one_short_line_and_no_compiler_commands(tmp_path):
    proc, output = _run(tmp_path)
    compiled = list((tmp_path / "cache" / "fenics").glob("libffcx_*.so"))
    assert len(compiled) >= 5, "the private cache was not used: nothing was compiled"
    assert "INFO:" not in output and "build_ext" not in output and "libffcx_" not in output, output
    assert proc.stdout.count(MESSAGE) == 1, output

    # Second build on the now filled cache: nothing compiled, so no line at all.
    proc, output = _run(tmp_path)
    assert MESSAGE not in output and "INFO:" not in output, output
    assert len(list((tmp_path / "cache" / "fenics").glob("libffcx_*.so"))) == len(compiled)
