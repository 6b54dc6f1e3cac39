"""A corpus of bad inputs, each refused by validation alone with exit 2 and one line that
names what is wrong.

Every entry starts from a shipped case of one of the seven kinds (``runs/*.toml``, copied
into a temporary folder with the packing it uses) and breaks one thing: a value through
``--set``, the case text, a packing, a mesh or the output folder. Each entry is checked
twice, with ``cosim check`` and with ``cosim run``: both must stop in validation with the
same message (check-OK means the run starts; a refused run writes nothing). No entry runs
a simulation.
"""
import shutil
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

from cosim.cli import main

RUNS = Path(__file__).parents[2] / "runs"
BASES = {"dem": "demo_dem_settling.toml", "fe": "fe_footing.toml", "shear": "direct_shear_small.toml",
         "coupled": "coupled_footing_on_sand.toml", "footing": "footing_small.toml",
         "triaxial": "triaxial_small.toml", "embedded": "retaining_wall_small.toml", "clumps": "demo_dem_clumps.toml"}


@dataclass
class Bad:
    """One bad input: the base case, what is done to it, and a fragment of the message."""
    base: str
    fragment: str
    sets: list = field(default_factory=list)                 # --set overrides
    edit: tuple = ()                                          # (old, new) replacements in the case text
    append: str = ""                                          # text added at the end of the case
    files: dict = field(default_factory=dict)                 # name -> bytes, or a callable(path) writing it
    cut: str = None                                           # drop the section that starts with this
    raw: bytes = None                                         # the whole case file, as bytes
    out: str = None                                           # --out, relative to the folder ("{tmp}")
    label: str = ""

    def __str__(self):
        return self.label or f"{self.base}: {' '.join(self.sets) or self.edit or self.append or self.fragment}"


def npz(**arrays):
    return lambda path: np.savez(path, **arrays)


def text_packing(rows):
    return "\n".join(rows).encode() + b"\n"


PACKING_OK = ["0.01 0.01 0.01 0.001", "0.015 0.01 0.01 0.001", "0.02 0.02 0.01 0.0012"]
DEM_FILE = (('source = "cloud"', 'source = "file"\nfile = "bed.txt"'),
            ("count = 3000\n", ""), ("box = [[0.0, 0.0, 0.0], [0.03, 0.03, 0.06]]\n", ""),
            ("radius = [0.0008, 0.0012]  # m\n", ""))
SHEAR_FILE = (("[specimen]\n", '[specimen]\nsource = "file"\nfile = "specimen.npz"\n'),)
NO_HEIGHT = (("sample_height = 0.025", ""),)
SPECIMEN_FILE = '[specimen]\nsource = "file"\nfile = "specimen.npz"\n'
LONG_NAME = "ä" * 200

CLUMP_ROD = "members = [[-0.25, 0.0, 0.0, 0.5], [0.25, 0.0, 0.0, 0.5]]"

CORPUS = [
    # ---------------------------------------------------------------- grains with shape (clumps)
    Bad("shear", "grains = 'clumps' need at least one [[dem.clumps]] grain shape",
        edit=(("[specimen]\n", '[specimen]\ngrains = "clumps"\n'),), label="clumps: a clumped specimen with no shape"),
    Bad("shear", "zone_stress is for a zone fill (kinds embedded and footing)",
        sets=['specimen.zone_stress="weight"']),
    Bad("embedded", "'specimen.zone_stress'", sets=['specimen.zone_stress="settled"']),
    Bad("shear", "grain shapes need [specimen] grains = 'clumps'", append=f"\n[[dem.clumps]]\n{CLUMP_ROD}\n",
        label="clumps: a shape for a specimen of spheres"),
    Bad("triaxial", "not less than half the specimen",
        edit=(("[specimen]\n", '[specimen]\ngrains = "clumps"\n'),),
        append="\n[[dem.clumps]]\nmembers = [" + ", ".join(f"[{0.9 * k:.1f}, 0.0, 0.0, 0.5]" for k in range(9)) + "]\n",
        label="clumps: a nine-sphere rod (24 mm at the largest sieve size) longer than half the 40 mm cell"),
    Bad("triaxial", "x the critical step", sets=["time.dt=1.2e-5"],
        edit=(("[specimen]\n", '[specimen]\ngrains = "clumps"\n'),),
        append="\n[[dem.clumps]]\nmembers = [[-0.5, 0.0, 0.0, 0.5], [0.5, 0.0, 0.0, 0.5]]\n",
        label="clumps: a time step the spheres of the sieve curve take but its two-sphere grains do not"),
    Bad("footing", "at least 3 of the largest clumped grains' lengths",
        edit=(("[specimen]\n", '[specimen]\ngrains = "clumps"\n'),), append=f"\n[[dem.clumps]]\n{CLUMP_ROD}\n",
        label="clumps: rods too long for the footing's 10 mm slice (three rod lengths are needed)"),
    Bad("shear", "'specimen.grains' = 'clumps': not used here: source = 'file' takes the specimen", cut="[specimen]",
        append=f'\n[specimen]\ngrains = "clumps"\nsource = "file"\nfile = "packings/sand_bed_30mm.npz"\n'
               f"\n[[dem.clumps]]\n{CLUMP_ROD}\n", label="clumps: grains = 'clumps' with a packing file"),
    Bad("clumps", "dem.clumps", edit=((CLUMP_ROD, "members = []"),), label="clumps: a template with no members"),
    Bad("clumps", "member 1 of the clump template has radius 0.0",
        edit=((CLUMP_ROD, "members = [[-0.25, 0.0, 0.0, 0.5], [0.25, 0.0, 0.0, 0.0]]"),)),
    Bad("clumps", "member 0 of the clump template has radius -0.5",
        edit=((CLUMP_ROD, "members = [[-0.25, 0.0, 0.0, -0.5], [0.25, 0.0, 0.0, 0.5]]"),)),
    Bad("clumps", "member 1 of the clump template does not touch the others",
        edit=((CLUMP_ROD, "members = [[-0.25, 0.0, 0.0, 0.5], [2.0, 0.0, 0.0, 0.5]]"),)),
    Bad("clumps", "four numbers", edit=((CLUMP_ROD, "members = [[-0.25, 0.0, 0.0], [0.25, 0.0, 0.0, 0.5]]"),)),
    Bad("clumps", "not less than the box's smallest side",
        sets=["dem.particles.box=[[0.0, 0.0, 0.0], [0.003, 0.03, 0.06]]"],
        label="clumps: a grain (a 3.5 mm rod) longer than the box is wide (3 mm)"),
    Bad("clumps", "are made by source = 'cloud'", edit=(('source = "cloud"', 'source = "file"\nfile = "bed.txt"'),
                                                         ("count = 800                # grains\n", ""),
                                                         ("box = [[0.0, 0.0, 0.0], [0.03, 0.03, 0.06]]\n", ""),
                                                         ("radius = [0.0010, 0.0014]  # m, each grain's equal-volume "
                                                          "radius\n", "")),
        files={"bed.txt": text_packing(PACKING_OK)}),
    Bad("clumps", "need [dem.particles] grains = 'clumps'", edit=(('grains = "clumps"', 'grains = "spheres"'),)),
    Bad("clumps", "need at least one [[dem.clumps]]",
        edit=(("[[dem.clumps]]             # a rod: two equal spheres, length / width = 1.5\n" + CLUMP_ROD
               + "\nshare = 1.0\n", ""),
              ("[[dem.clumps]]             # a bent grain of three spheres\nmembers = [[0.0, 0.0, 0.0, 0.5], "
               "[0.6, 0.0, 0.0, 0.4], [0.0, 0.45, 0.15, 0.35]]\nshare = 1.0\n", "")),
        label="clumps: no grain shape"),
    Bad("clumps", "dem.particles.grains", sets=['dem.particles.grains="cubes"']),
    Bad("clumps", "dem.clumps[0].share", sets=["dem.clumps[0].share=0.0"]),
    # ---------------------------------------------------------------- the case file itself
    Bad("dem", "UTF-8", raw=b'[case]\nname = "caf\xe9"\nkind = "dem"\n', label="not UTF-8"),
    Bad("dem", "valid TOML", raw=b"[case\nname = 1\n", label="TOML syntax error"),
    Bad("dem", "valid TOML", raw=b'[case]\nname = "a"\nname = "b"\n', label="duplicate key"),
    Bad("dem", "'case' = None: required", raw=b'[time]\nsteps = 1\n', label="no [case]"),
    Bad("dem", "needs a [dem] section", raw=b'[case]\nname = "x"\nkind = "dem"\n[time]\nsteps = 1\n',
        label="no [dem]"),
    # ---------------------------------------------------------------- [case]
    Bad("dem", "case.name", sets=['case.name="../../../x"']),
    Bad("dem", "case.name", sets=['case.name="/tmp/abs"']),
    Bad("dem", "case.name", sets=[f'case.name="{LONG_NAME}"'], label="200-character non-ASCII name"),
    Bad("dem", "case.name", sets=['case.name=""']),
    Bad("dem", "case.name", sets=['case.name="a b"']),
    Bad("dem", "case.name", sets=["case.name=5"]),
    Bad("dem", "case.kind", sets=['case.kind="dems"']),
    Bad("dem", "case.seed", sets=["case.seed=-1"]),
    Bad("dem", "case.seed", sets=["case.seed=1.5"]),
    # ---------------------------------------------------------------- [time]
    Bad("dem", "time.duration", sets=["time.duration=inf"]),
    Bad("dem", "time.duration", sets=["time.duration=nan"]),
    Bad("dem", "time.duration", sets=["time.duration=-0.1"]),
    Bad("dem", "steps per run", sets=["time.duration=1e30"]),
    Bad("dem", "exactly one", sets=["time.steps=100"]),
    Bad("dem", "time.steps", sets=["time.steps=1.5"]),
    Bad("dem", "critical step", sets=["time.dt=1e-3"]),
    Bad("dem", "time.dt", sets=["time.dt=-1e-6"]),
    Bad("dem", "time.dt", sets=["time.dt=inf"]),
    Bad("dem", "time.safety_factor", sets=["time.safety_factor=0.9"]),
    Bad("dem", "time.safety_factor", sets=["time.safety_factor=nan"]),
    Bad("dem", "time.colour", sets=["time.colour=1"]),
    # ---------------------------------------------------------------- [output]
    Bad("dem", "output.interval", sets=["output.interval=-1.0"]),
    Bad("dem", "must not exceed", sets=["output.interval=10.0"]),
    Bad("dem", "output.vtk", sets=['output.vtk="yes"']),
    Bad("dem", "output.vtk", sets=["output.vtk=1"]),
    Bad("dem", "output.checkpoint_interval", sets=["output.checkpoint_interval=0.0"]),
    Bad("dem", "output.progress_interval", sets=["output.progress_interval=inf"]),
    Bad("dem", "unknown key", sets=["output.format='vtk'"]),
    # ---------------------------------------------------------------- [dem]
    Bad("dem", "dem.contact_law", sets=['dem.contact_law="hooke"']),
    Bad("dem", "dem.gravity", sets=["dem.gravity=[nan, 0.0, -9.81]"]),
    Bad("dem", "dem.gravity", sets=["dem.gravity=[0.0, -9.81]"]),
    Bad("dem", "dem.gravity", sets=['dem.gravity="down"']),
    Bad("dem", "dem.local_damping", sets=["dem.local_damping=1.0"]),
    Bad("dem", "dem.local_damping", sets=["dem.local_damping=-0.1"]),
    Bad("dem", "dem.viscous_damping", sets=["dem.viscous_damping=inf"]),
    Bad("dem", "dem.materials[0].density", sets=["dem.materials[0].density=inf"]),
    Bad("dem", "dem.materials[0].density", sets=["dem.materials[0].density=0.0"]),
    Bad("dem", "dem.materials[0].young", sets=["dem.materials[0].young=inf"]),
    Bad("dem", "dem.materials[0].young", sets=["dem.materials[0].young=-5.0"]),
    Bad("dem", "dem.materials[0].poisson", sets=["dem.materials[0].poisson=0.5"]),
    Bad("dem", "dem.materials[0].friction", sets=["dem.materials[0].friction=-1"]),
    Bad("dem", "dem.materials[0].friction", sets=["dem.materials[0].friction=nan"]),
    Bad("dem", "dem.materials[0].restitution", sets=["dem.materials[0].restitution=0.0"]),
    Bad("dem", "dem.materials[0].restitution", sets=["dem.materials[0].restitution=1.5"]),
    Bad("dem", "dem.materials[0].stiffness_ratio", sets=["dem.materials[0].stiffness_ratio=0.0"]),
    Bad("dem", "dem.materials[0].rolling_stiffness", sets=["dem.materials[0].rolling_stiffness=-1.0"]),
    Bad("dem", "unknown key", sets=['dem.materials[0].colour="red"']),
    Bad("dem", "index 5", sets=["dem.materials[5].friction=0.3"]),
    Bad("dem", "section.list[i].key", sets=["dem.materials.friction=0.3"]),
    Bad("dem", "must be unique", append='[[dem.materials]]\nname = "sand"\ndensity = 1.0\nyoung = 1.0\n'),
    Bad("dem", "dem.particles.count", sets=["dem.particles.count=0"]),
    Bad("dem", "dem.particles.count", sets=['dem.particles.count="abc"']),
    Bad("dem", "smaller than the box", sets=["dem.particles.radius=[0.01, 0.02]"]),
    Bad("dem", "r_min <= r_max", sets=["dem.particles.radius=[0.002, 0.001]"]),
    Bad("dem", "r_min <= r_max", sets=["dem.particles.radius=[0.0, 0.001]"]),
    Bad("dem", "max corner", sets=["dem.particles.box=[[0.0, 0.0, 0.0], [0.0, 0.03, 0.06]]"]),
    Bad("dem", "dem.particles.box", sets=["dem.particles.box=[[0.0, 0.0, 0.0], [0.03, 0.03, nan]]"]),
    Bad("dem", "dem.particles.velocity", sets=["dem.particles.velocity=[inf, 0.0, 0.0]"]),
    Bad("dem", "must be one of the materials", sets=['dem.particles.material="steel"']),
    Bad("dem", "dem.particles.source", sets=['dem.particles.source="grid"']),
    Bad("dem", "not used here", sets=['dem.particles.file="bed.npz"']),
    Bad("dem", "must be one of the materials", sets=['dem.walls[0].material="steel"']),
    Bad("dem", "non-zero", sets=["dem.walls[0].normal=[0.0, 0.0, 0.0]"]),
    Bad("dem", "dem.walls[0].normal", sets=["dem.walls[0].normal=[nan, 0.0, 1.0]"]),
    Bad("dem", "dem.walls[0].point", sets=["dem.walls[0].point=[0.0, 0.0, inf]"]),
    Bad("dem", "dem.walls[0].type", sets=['dem.walls[0].type="sphere"']),
    Bad("dem", "not used here", sets=['dem.walls[0].file="floor.stl"']),
    Bad("dem", "dem.walls[0].velocity", sets=["dem.walls[0].velocity=[0.0, 0.0, nan]"]),
    Bad("dem", "file not found", append='[[dem.walls]]\ntype = "facets"\nfile = "none.stl"\nmaterial = "sand"\n'),
    Bad("dem", "could not read the triangle mesh", files={"junk.stl": b"solid x\nthis is not an stl\n"},
        append='[[dem.walls]]\ntype = "facets"\nfile = "junk.stl"\nmaterial = "sand"\n'),
    Bad("dem", "not used here", files={"junk.stl": b""},
        append='[[dem.walls]]\ntype = "facets"\nfile = "junk.stl"\npoint = [0.0, 0.0, 0.0]\nmaterial = "sand"\n'),
    Bad("dem", "does not use [specimen]", sets=["specimen.void_ratio=0.7"]),
    Bad("dem", "does not use [fe]", sets=['fe.mesh="block.geo"']),
    Bad("dem", "does not use [coupling]", sets=['coupling.material="sand"']),
    Bad("dem", "--set needs the form", sets=["dem.local_damping"]),
    Bad("dem", "--set needs section.key", sets=["dem..x=1"]),
    Bad("dem", "is a value, not a table", sets=["dem.local_damping.x=1"]),
    # ---------------------------------------------------------------- packing files (dem)
    Bad("dem", "file not found", edit=DEM_FILE),
    Bad("dem", "allowed formats", edit=DEM_FILE + (("bed.txt", "bed.csv"),), files={"bed.csv": b"1,2,3,4\n"}),
    Bad("dem", "NaN or infinite", edit=DEM_FILE, files={"bed.txt": text_packing(PACKING_OK + ["0.01 nan 0.02 0.001"])},
        label="packing with a NaN coordinate"),
    Bad("dem", "sphere 2", edit=DEM_FILE,
        files={"bed.txt": text_packing(["0.01 0.01 0.01 0.001", "0.01 0.02 0.01 inf"])},
        label="packing with an infinite radius"),
    Bad("dem", "no spheres", edit=DEM_FILE, files={"bed.txt": b"# x y z r\n"}, label="empty packing"),
    Bad("dem", "4 columns", edit=DEM_FILE, files={"bed.txt": text_packing(["0.01 0.01 0.01"] * 3)}),
    Bad("dem", "sphere 2 has 3 numbers", edit=DEM_FILE,
        files={"bed.txt": text_packing(["0.01 0.01 0.01 0.001", "0.02 0.01 0.01"])}, label="ragged packing"),
    Bad("dem", "not a row of numbers", edit=DEM_FILE,
        files={"bed.txt": text_packing(["0.01 0.01 0.01 0.001", "x y z r"])}),
    Bad("dem", "radius <= 0", edit=DEM_FILE, files={"bed.txt": text_packing(["0.01 0.01 0.01 -0.001"])}),
    Bad("dem", "not UTF-8", edit=DEM_FILE, files={"bed.txt": b"0.01 0.01 0.01 0.001 \xff\xfe\n"}),
    Bad("dem", "'positions' must be (n, 3)", edit=DEM_FILE + (("bed.txt", "bed.npz"),),
        files={"bed.npz": npz(positions=np.zeros((5, 3)), radii=np.full(4, 1e-3))}, label="npz lengths differ"),
    Bad("dem", "no array 'radii'", edit=DEM_FILE + (("bed.txt", "bed.npz"),),
        files={"bed.npz": npz(positions=np.zeros((5, 3)))}),
    Bad("dem", "could not read the packing", edit=DEM_FILE + (("bed.txt", "bed.npz"),),
        files={"bed.npz": b"not a zip file"}),
    Bad("dem", "is empty (0 bytes)", edit=DEM_FILE + (("bed.txt", "bed.npz"),), files={"bed.npz": b""},
        label="zero-length .npz packing"),
    Bad("shear", "is empty (0 bytes)", cut="[specimen]", append=SPECIMEN_FILE, edit=NO_HEIGHT,
        files={"specimen.npz": b""}, label="shear: zero-length .npz specimen"),
    Bad("dem", "not used here", edit=DEM_FILE[:1], files={"bed.txt": text_packing(PACKING_OK)},
        label="file packing with count/box/radius"),
    # ---------------------------------------------------------------- --out
    Bad("dem", "is a file", files={"taken": b"x"}, out="taken"),
    Bad("dem", "lies under", files={"taken": b"x"}, out="taken/run"),
    Bad("dem", "cannot write", out="/proc/cosim-out"),
    # ---------------------------------------------------------------- fe
    Bad("fe", "mesh not found", sets=['fe.mesh="nope.geo"']),
    Bad("fe", "allowed formats", sets=['fe.mesh="shape.step"'], files={"shape.step": b"x"}),
    Bad("fe", "fe.mesh_size", sets=["fe.mesh_size=0.0"]),
    Bad("fe", "fe.mesh_size", sets=["fe.mesh_size=nan"]),
    Bad("fe", "fe.materials[0].E", sets=["fe.materials[0].E=inf"]),
    Bad("fe", "fe.materials[0].nu", sets=["fe.materials[0].nu=0.5"]),
    Bad("fe", "fe.materials[1].rho", sets=["fe.materials[1].rho=-1.0"]),
    Bad("fe", "not a volume physical group", sets=['fe.materials[0].group="rock"']),
    Bad("fe", "not a surface physical group", sets=['fe.boundary_conditions[0].boundary="floor"']),
    Bad("fe", "fe.boundary_conditions[0].components", sets=["fe.boundary_conditions[0].components=[3]"]),
    Bad("fe", "needs velocity", sets=['fe.boundary_conditions[0].type="velocity"']),
    Bad("fe", "not used here", sets=["fe.boundary_conditions[0].velocity=[1.0, 0.0, 0.0]"]),
    Bad("fe", "fe.loads[0].pressure", sets=["fe.loads[0].pressure=nan"]),
    Bad("fe", "fe.loads[0].pressure", sets=["fe.loads[0].pressure=inf"]),
    Bad("fe", "not used here", sets=["fe.loads[0].traction=[0.0, 0.0, 1.0]"]),
    Bad("fe", "not a surface physical group", sets=['fe.loads[0].boundary="nowhere"']),
    Bad("fe", "needs traction", edit=(('type = "pressure"', 'type = "traction"'), ("pressure = 100.0e3", "")),
        label="traction load without its vector"),
    Bad("fe", "fe.loads[0].ramp", sets=["fe.loads[0].ramp=0.0"]),
    Bad("fe", "local non-viscous damping", sets=["fe.damping.alpha=1.0"]),
    Bad("fe", "fe.damping.type", sets=['fe.damping.type="rayleigh"']),
    Bad("fe", "unstable above", sets=["fe.alpha_tau=100.0"]),
    Bad("fe", "fe.formulation", sets=['fe.formulation="quadratic"']),
    Bad("fe", "defines no such parameter", sets=["fe.geometry_parameters.Q=1.0"]),
    Bad("fe", "fe.geometry_parameters", sets=["fe.geometry_parameters.B=nan"]),
    Bad("fe", "not a surface physical group", sets=['fe.reactions=["top_of_world"]']),
    Bad("fe", "not used here", sets=["output.vtk=false"]),
    Bad("fe", "does not use [dem]", sets=["dem.gravity=[0.0, 0.0, -9.81]"]),
    Bad("fe", "not used here", sets=['fe.mesh="m.msh"', "fe.mesh_size=0.1"], files={"m.msh": b"x"}),
    Bad("fe", "critical step", sets=["time.dt=1.0"]),
    Bad("fe", "names no physical groups", sets=['fe.mesh="junk.msh"'],
        files={"junk.msh": b"$MeshFormat\ngarbage\n"}, edit=(("mesh_size = 0.2", ""),), label="garbage .msh"),
    Bad("fe", "not a gmsh .msh file", sets=['fe.mesh="junk.msh"'], files={"junk.msh": b"\x00\x01binary"},
        edit=(("mesh_size = 0.2", ""),), label="binary junk as .msh"),
    Bad("fe", "cannot be meshed", sets=['fe.mesh="junk.msh"'], edit=(("mesh_size = 0.2", ""),),
        files={"junk.msh": b'$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$PhysicalNames\n5\n3 1 "soil"\n3 2 "footing"\n'
                           b'2 3 "soil_bottom"\n2 4 "soil_sides"\n2 5 "footing_top"\n$EndPhysicalNames\n'
                           b'$Nodes\nbroken\n'},
        label=".msh with names but broken nodes"),
    Bad("fe", "cannot be meshed", sets=['fe.mesh="broken.geo"'],
        files={"broken.geo": b'Box(1) = {0, 0, 0, 1, 1;\nPhysical Volume("soil") = {1};\n'
                             b'Physical Volume("footing") = {1};\nPhysical Surface("soil_bottom") = {1};\n'
                             b'Physical Surface("soil_sides") = {2};\nPhysical Surface("footing_top") = {3};\n'},
        label=".geo syntax error"),
    Bad("fe", "cannot be meshed", sets=["fe.geometry_parameters.B=0.0", "fe.geometry_parameters.b=0.0"],
        label=".geo parameters that leave no volume"),
    Bad("fe", "fe.geometry_parameters.B' = -2.0: must be >= 0: footing.geo declares no lower bound",
        sets=["fe.geometry_parameters.B=-2.0"], label="negative .geo length"),
    Bad("fe", "fe.geometry_parameters.t' = -0.1: must be >= 0", sets=["fe.geometry_parameters.t=-0.1"],
        label="negative .geo thickness"),
    Bad("fe", "outside the range [0.5, 2] limits.geo declares for a", sets=['fe.mesh="limits.geo"', "fe.mesh_size=0.5",
        "fe.geometry_parameters.a=3.0"], files={"limits.geo": b'SetFactory("OpenCASCADE");\n'
        b'DefineConstant[ a = {1.0, Min 0.5, Max 2, Name "Parameters/a"} ];\nBox(1) = {0, 0, 0, a, a, a};\n'
        b'Physical Volume("soil") = {1};\nPhysical Surface("soil_bottom") = {5};\n'},
        label=".geo parameter above its declared Max"),
    Bad("fe", "fe.mesh_size' = 5.0: larger than the whole geometry of footing.geo (its largest extent is 2",
        sets=["fe.mesh_size=5.0"], label="mesh size larger than the geometry"),
    Bad("coupled", "fe.mesh_size' = 1.0: larger than the whole geometry of block.geo (its largest extent is 0.02",
        sets=["fe.mesh_size=1.0"], label="coupled: mesh size larger than the geometry"),
    # ---------------------------------------------------------------- direct_shear
    Bad("shear", "smaller than box_length", sets=["direct_shear.sample_height=0.07"]),
    Bad("shear", "smaller than box_length", sets=["direct_shear.shear_distance=0.07"]),
    Bad("shear", "smaller than shear_distance", sets=["direct_shear.ramp_distance=0.01"]),
    Bad("shear", "direct_shear.normal_stress", sets=["direct_shear.normal_stress=inf"]),
    Bad("shear", "must be one of the materials", sets=['direct_shear.sand_material="clay"']),
    Bad("shear", "give only time.dt", sets=["time.duration=1.0"]),
    Bad("shear", "specimen.void_ratio", sets=["specimen.void_ratio=2.0"]),
    Bad("shear", "allowed presets", sets=['specimen.sieve="beach"']),
    Bad("shear", "give both or neither", sets=["specimen.sieve_diameters=[0.001, 0.002]"]),
    Bad("shear", "below half the sample height", sets=["direct_shear.sample_height=0.01"]),
    Bad("shear", "not used here", sets=["output.interval=0.1"]),
    Bad("shear", "no layers, no compaction plate", sets=['specimen.method="radius_expansion"', "specimen.layers=3"]),
    Bad("shear", "remove [dem.particles]",
        append='[dem.particles]\nsource = "cloud"\ncount = 1\nbox = [[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]]\n'
               'radius = [0.1, 0.1]\nmaterial = "sand"\n'),
    Bad("shear", "does not use [fe]", sets=['fe.mesh="block.geo"']),
    Bad("shear", "direct_shear.rows", sets=["direct_shear.rows=5"]),
    Bad("shear", "critical step", sets=["time.dt=1.0"]),
    Bad("shear", "file not found", cut="[specimen]", append=SPECIMEN_FILE, edit=NO_HEIGHT),
    Bad("shear", "not used here", edit=SHEAR_FILE + NO_HEIGHT, files={"specimen.npz": npz(
        positions=np.zeros((1, 3)) + 0.01, radii=np.full(1, 1e-3))}, label="file specimen with generation keys"),
    Bad("shear", "the height is the packing's", cut="[specimen]", append=SPECIMEN_FILE,
        files={"specimen.npz": npz(positions=np.zeros((1, 3)) + 0.01, radii=np.full(1, 1e-3))},
        label="file specimen with sample_height"),
    Bad("shear", "inside the 0.06 m x 0.06 m box", cut="[specimen]", append=SPECIMEN_FILE, edit=NO_HEIGHT,
        files={"specimen.npz": npz(positions=np.array([[0.07, 0.01, 0.01]]), radii=np.full(1, 1e-3))}),
    Bad("shear", "NaN or infinite", cut="[specimen]", append=SPECIMEN_FILE, edit=NO_HEIGHT,
        files={"specimen.npz": npz(positions=np.array([[0.01, np.nan, 0.01]]), radii=np.full(1, 1e-3))}),
    # ---------------------------------------------------------------- coupled
    Bad("coupled", "not used here", sets=["time.dt=1e-6"], label="time.dt in a coupled case"),
    Bad("coupled", "the exact limit 2/omega_max is the displacement formulation's",
        sets=["time.fe_safety_factor=0.8"], label="the FE's exact step with the mixed formulation"),
    Bad("embedded", "less than or equal to 0.9", sets=["time.fe_safety_factor=0.95"],
        label="an FE safety factor above 0.9"),
    Bad("dem", "sets the explicit FE's step beside the grains", sets=["time.fe_safety_factor=0.8"],
        label="an FE safety factor without an FE"),
    Bad("coupled", "output.checkpoint_interval", sets=["output.checkpoint_interval=0.0"]),
    Bad("coupled", "not a surface physical group", sets=['coupling.interface=["nowhere"]']),
    Bad("coupled", "must be one of the materials", sets=['coupling.material="steel"']),
    Bad("coupled", "coupling.subcycles", sets=["coupling.subcycles=0"]),
    Bad("coupled", "'replicated' or 'distributed'", sets=['coupling.fe_partition="both"']),
    # dt_DE = dt_FE / subcycles is never above time.safety_factor (<= 0.5) x its critical step
    Bad("coupled", "time.safety_factor", sets=["time.safety_factor=0.9"], label="dt_DE above half its critical step"),
    Bad("coupled", "needs a [coupling] section", cut="[coupling]", label="no [coupling]"),
    Bad("coupled", "file not found", sets=['dem.particles.file="missing.npz"']),
    Bad("coupled", "does not use [specimen]", sets=["specimen.scale=2.0"]),
    Bad("coupled", "fe.materials[0].E", sets=["fe.materials[0].E=nan"]),
    # ---------------------------------------------------------------- embedded (docs/guide/own-geometry.md)
    Bad("embedded", "no physical volume 'backfill' in the model", edit=(('group = "soil"', 'group = "backfill"'),),
        label="a role mapped to a volume the model does not have"),
    Bad("embedded", "physical group 'top' is not a volume", edit=(('group = "soil"', 'group = "top"'),),
        label="a volume role mapped to a surface"),
    Bad("embedded", "no physical surface 'roof'", edit=(('group = "base"', 'group = "roof"'),)),
    Bad("embedded", "this group already has a role", edit=(('group = "far"', 'group = "base"'),),
        label="a group given two roles"),
    Bad("embedded", "shares no face with an FE volume", sets=['embedded.mesh="apart.geo"'],
        files={"apart.geo": b'SetFactory("OpenCASCADE");\nBox(1) = {0, 0, 0, 0.05, 0.01, 0.06};\n'
                            b'Box(2) = {0.1, 0, 0, 0.04, 0.01, 0.06};\nPhysical Volume("zone") = {1};\n'
                            b'Physical Volume("soil") = {2};\n'},
        label="a zone with no interface face"),
    Bad("embedded", "at least 3 of the largest grains", sets=["embedded.parameters.Ly=0.006"],
        label="a zone thinner than 3 grains"),
    Bad("embedded", "could not be meshed", sets=['embedded.mesh="broken.geo"'],
        files={"broken.geo": b"Point(1) = {0, 0, 0;\n"}, label="an unmeshable .geo"),
    Bad("embedded", "filled by 'radius_expansion'", sets=['specimen.method="under_compaction"']),
    Bad("embedded", "a 'soil' volume needs E", edit=(("E = 2.0e6\n", ""),)),
    Bad("embedded", "a DEM wall needs a material", edit=(('material = "side_wall"', ""),)),
    Bad("embedded", "give it a velocity", edit=(("velocity = [-0.00125, 0.0, 0.0]",
                                                 "seating_pressure = 100.0\nvelocity = [0.0, 0.0, 0.0]"),),
        label="a body placed on the grains without a velocity"),
    Bad("embedded", "a zone is made of grains", sets=["embedded.volumes[0].K0=0.5"], label="K0 given for a zone"),
    Bad("embedded", "no physical surface 'roof'", sets=['embedded.ground="roof"'],
        label="a ground surface not in the model"),
    Bad("embedded", "greater than 0", sets=["embedded.volumes[1].K0=-0.5"], label="a negative K0"),
    Bad("embedded", "mass scaling is for a stiff structure", sets=["embedded.volumes[1].inertia_scale=100.0"],
        label="mass scaling of the FE soil"),
    Bad("embedded", "greater than or equal to 1", sets=["embedded.volumes[1].inertia_scale=0.5"],
        label="an inertia scale below 1"),
    Bad("embedded", "solved statically: 'displacement'", sets=['embedded.model="fe"'],
        label="the FE-only twin in the mixed formulation"),
    Bad("embedded", "rigid bodies move grains", sets=['embedded.model="fe"', 'embedded.formulation="displacement"'],
        label="the FE-only twin with a rigid body"),
    # ---------------------------------------------------------------- footing (docs/design.md §7)
    Bad("footing", "at least 3 of the largest grains", sets=["zone.depth=0.005"], label="zone shallower than 3 grains"),
    Bad("footing", "at least 3 of the largest grains", sets=["soil.thickness=0.004"],
        label="slice thinner than 3 grains"),
    Bad("footing", "narrower than the DEM zone", sets=["footing.width=0.11"], label="footing wider than the zone"),
    Bad("footing", "zone.width", sets=["zone.width=0.2"], label="zone wider than the block"),
    Bad("footing", "reaches the zone's bottom", sets=["footing.settlement=0.5", "footing.width=0.09"]),
    Bad("footing", "not used here", sets=["time.dt=1e-6"], label="time.dt in a footing case"),
    Bad("footing", "lasts until footing.settlement", sets=["time.duration=0.1"]),
    Bad("footing", "remove [dem.particles]", append='\n[dem.particles]\nsource = "file"\nfile = "x.npz"\n'
        'material = "sand"\n'),
    Bad("footing", "footing.model", sets=['footing.model="fem"']),
    Bad("footing", "filled by 'radius_expansion'", sets=['specimen.method="under_compaction"']),
    Bad("footing", "soil.E", sets=["soil.E=-1.0"]),
    Bad("footing", "lie outside the grain volumes", cut="[specimen]",
        append='\n[specimen]\nsource = "file"\nfile = "packings/sand_bed_30mm.npz"\n',
        label="a packing that does not fit the zone"),
    # ---------------------------------------------------------------- triaxial (docs/design.md §3.10)
    Bad("triaxial", "at least 6 of the largest grains", sets=["triaxial.size=0.02"], label="cell under 6 grains"),
    Bad("triaxial", "lasts until triaxial.axial_strain", sets=["time.steps=100"]),
    Bad("triaxial", "triaxial.ramp_strain", sets=["triaxial.ramp_strain=0.3"]),
    Bad("triaxial", "triaxial.axial_strain", sets=["triaxial.axial_strain=0.0"]),
    Bad("triaxial", "triaxial.cell_pressure", sets=["triaxial.cell_pressure=-100e3"]),
    Bad("triaxial", "triaxial.wall_material", sets=['triaxial.wall_material="rubber"']),
    Bad("triaxial", "not used here", sets=["output.interval=0.1"], label="output.interval in a triaxial case"),
    Bad("triaxial", "does not use [direct_shear]", append="\n[direct_shear]\nbox_length = 0.06\n"),
    Bad("triaxial", "specimen.deposition_material", sets=['specimen.deposition_material="clay"']),
    Bad("triaxial", "missing.npz", cut="[specimen]", append='\n[specimen]\nsource = "file"\nfile = "missing.npz"\n',
        label="triaxial: a packing file that does not exist"),
]


def write_case(bad, folder):
    text = (RUNS / BASES[bad.base]).read_text()
    for old, new in bad.edit:
        assert old in text, old
        text = text.replace(old, new, 1)
    if bad.cut:
        start = text.index(bad.cut)
        end = text.find("\n[", start + 1)
        text = text[:start] + (text[end + 1:] if end >= 0 else "")
    text += bad.append
    path = folder / "case.toml"
    path.write_bytes(bad.raw if bad.raw is not None else text.encode())
    for name, content in bad.files.items():
        if callable(content):
            content(folder / name)
        else:
            (folder / name).write_bytes(content)
    return path


@pytest.fixture
def folder(tmp_path):
    shutil.copytree(RUNS / "packings", tmp_path / "packings")
    return tmp_path


def test_the_corpus_is_large_and_covers_every_kind():
    assert len(CORPUS) >= 100
    assert {bad.base for bad in CORPUS} == set(BASES)


@pytest.mark.parametrize("bad", CORPUS, ids=str)
def test_bad_input_is_refused_by_check_and_run_alike(bad, folder, capsys):
    case = write_case(bad, folder)
    sets = [arg for s in bad.sets for arg in ("--set", s)]
    out = ["--out", str(folder / bad.out) if not bad.out.startswith("/") else bad.out] if bad.out else []
    messages = []
    for command in ("check", "run"):
        target = out or (["--out", str(folder / "out")] if command == "run" else [])
        code = main([command, str(case), *sets, *target])
        captured = capsys.readouterr()
        lines = [line for line in captured.err.splitlines() if line.startswith("cosim: error:")]
        assert code == 2, f"{command}: exit {code}\n{captured.out}\n{captured.err}"
        assert len(lines) == 1 and "Traceback" not in captured.err, captured.err
        assert bad.fragment in lines[0], lines[0]
        messages.append(lines[0])
    assert messages[0] == messages[1]
    assert not (folder / "out").exists()       # a refused run writes nothing
