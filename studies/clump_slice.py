"""A vertical slice through a packing of clumps: the member spheres cut by the plane y = y0, drawn as
discs and coloured by the grain they belong to (the dem guide's picture of runs/demo_dem_clumps.toml).

    .venv/bin/cosim run runs/demo_dem_clumps.toml
    .venv/bin/python studies/clump_slice.py runs/out/demo_dem_clumps docs/dem_clumps_slice.png
"""
import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import PatchCollection  # noqa: E402
from matplotlib.patches import Circle  # noqa: E402


def slice_picture(out_dir, png, y0=None):
    """Discs of the spheres cut by y = y0 (default: the middle of the packing), one colour per grain."""
    out_dir = Path(out_dir)
    packing = np.load(out_dir / "final_packing.npz")
    positions, radii = packing["positions"], packing["radii"]
    member_of = np.load(out_dir / "final_clumps.npz")["member_of"]
    y0 = float(np.median(positions[:, 1])) if y0 is None else y0
    cut = np.abs(positions[:, 1] - y0) < radii
    disc = np.sqrt(radii[cut] ** 2 - (positions[cut, 1] - y0) ** 2)
    colours = plt.get_cmap("tab20")(np.random.default_rng(1).permutation(member_of.max() + 2)[member_of[cut] + 1] % 20)
    width = np.ptp(positions[:, 0]) + 2e-3
    height = positions[:, 2].max() + 1e-3
    fig, ax = plt.subplots(figsize=(7.0, 1.4 + 7.0 * height / width))
    patches = [Circle((x * 1e3, z * 1e3), r * 1e3) for x, z, r in zip(positions[cut, 0], positions[cut, 2], disc,
                                                                     strict=True)]
    ax.add_collection(PatchCollection(patches, facecolors=colours, edgecolors="k", linewidths=0.3))
    ax.set_xlim(positions[:, 0].min() * 1e3 - 1, positions[:, 0].max() * 1e3 + 1)
    ax.set_ylim(0, positions[:, 2].max() * 1e3 + 1)
    ax.set_aspect("equal")
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("z [mm]")
    ax.set_title(f"{member_of.max() + 1} grains of 2 and 3 spheres after settling: the slice y = {y0 * 1e3:.1f} mm,\n"
                 "one colour per grain (discs of one colour are one rigid grain)", fontsize=9)
    fig.tight_layout()
    fig.savefig(png, dpi=150)
    return png


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out_dir")
    parser.add_argument("png")
    args = parser.parse_args()
    print(slice_picture(args.out_dir, args.png))
