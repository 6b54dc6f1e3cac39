"""PNG plots of CSV time series (matplotlib, Agg backend: no display needed)."""
from __future__ import annotations

import csv

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def read_columns(csv_path):
    """A CSV file as ``{column: [float, ...]}``."""
    with open(csv_path) as f:
        rows = list(csv.DictReader(f))
    return {k: [float(r[k]) for r in rows] for k in rows[0]} if rows else {}


def plot_panels(csv_path, x, panels, png_path, title=""):
    """One panel per entry of ``panels`` = ``[(ylabel, [columns], log_y), ...]`` against column ``x``."""
    data = read_columns(csv_path)
    fig, axes = plt.subplots(len(panels), 1, figsize=(7, 2.6 * len(panels)), sharex=True, squeeze=False)
    for ax, (ylabel, columns, log_y) in zip(axes[:, 0], panels, strict=True):
        for c in columns:
            values = data[c]
            ax.plot(data[x], [abs(v) for v in values] if log_y else values, label=c)
        ax.set_ylabel(ylabel)
        if log_y:
            ax.set_yscale("log")
        ax.grid(True, alpha=0.3)
        if len(columns) > 1:
            ax.legend(fontsize=7, ncol=3)
    axes[-1, 0].set_xlabel(x)
    if title:
        axes[0, 0].set_title(title)
    fig.tight_layout()
    fig.savefig(png_path, dpi=120)
    plt.close(fig)
