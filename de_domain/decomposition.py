"""Spatial decomposition of the particles over MPI ranks: slabs by particle count.

The domain is cut along one axis (the one along which the particles spread most)
into ``size`` slabs holding equal numbers of particles: slab r is
``cuts[r] ≤ x < cuts[r + 1]`` with ``cuts[0] = −∞`` and ``cuts[size] = +∞``, so
every point of space has exactly one owner. A rank also keeps ghost copies of
the particles that lie within ``width`` (the largest interaction range plus the
skin, 2 r_max + s) of its slab.

Why slabs and not recursive coordinate bisection: on the machines this project
targets (2 cores, ≤ 4 ranks oversubscribed) and for the beds of geomechanics
(wider than deep), slabs give each rank at most two neighbours and the smallest
number of messages; recursive bisection only pays once a slab becomes thinner
than a few ghost widths (see the scaling model in docs/performance.md). Nothing
below depends on slabs except :meth:`SlabDecomposition.owner` and
:meth:`SlabDecomposition.ghost_ranks`. Results never depend on the decomposition
(de_domain.distributed), only the speed does.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

REBALANCE_IMBALANCE = 1.10  # re-cut when the largest rank holds more than this × the mean


@dataclass(frozen=True)
class SlabDecomposition:
    axis: int
    cuts: np.ndarray  # (size + 1,): −inf, interior cuts ascending, +inf
    width: float      # ghost layer width

    @property
    def size(self):
        return self.cuts.size - 1

    def owner(self, pos):
        """Rank owning each position (n, 3)."""
        return np.searchsorted(self.cuts[1:-1], pos[:, self.axis], side="right").astype(np.int64)

    def ghost_ranks(self, pos, rank):
        """(n, size) bool: rank r ≠ ``rank`` keeps a ghost copy of each position (within
        ``width`` of slab r, i.e. cuts[r] − width ≤ x < cuts[r + 1] + width)."""
        x = pos[:, self.axis][:, None]
        inside = (x >= self.cuts[None, :-1] - self.width) & (x < self.cuts[None, 1:] + self.width)
        inside[:, rank] = False
        return inside


def balanced_cuts(coordinates, size):
    """Interior cuts putting ⌈n/size⌉-sized runs of the sorted ``coordinates`` in each
    slab (a cut halfway between neighbours; equal coordinates stay together)."""
    x = np.sort(np.asarray(coordinates, np.float64))
    cuts = np.full(size + 1, np.inf)
    cuts[0] = -np.inf
    n = x.size
    for r in range(1, size):
        k = (r * n) // size
        if n == 0:
            cuts[r] = 0.0
        elif k <= 0:
            cuts[r] = x[0]
        elif k >= n:
            cuts[r] = np.nextafter(x[-1], np.inf)
        else:
            cuts[r] = 0.5 * (x[k - 1] + x[k]) if x[k] > x[k - 1] else x[k]
    return np.maximum.accumulate(cuts)


def spread_axis(lo, hi):
    """The axis along which the box [lo, hi] is longest."""
    return int(np.argmax(np.asarray(hi) - np.asarray(lo)))


def needs_rebalance(counts):
    """Whether the owned-particle counts per rank are uneven enough to re-cut."""
    counts = np.asarray(counts, np.float64)
    mean = counts.mean() if counts.size else 0.0
    return bool(mean > 0.0 and counts.max() > REBALANCE_IMBALANCE * mean)
