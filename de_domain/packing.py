"""Specimen building blocks: sieve-curve size distributions, random non-overlapping
clouds, and packing files (docs/design.md §3.1).

Packing files: ``.npz`` (arrays ``positions`` (n,3), ``radii`` (n,), optional
metadata), plain text ``x y z r`` per line (as YADE ``ymport.text``, LIGGGHTS
``read_data``-style scripts and ESyS-Particle exchange them), and LIGGGHTS dumps
whose ``ITEM: ATOMS`` header names ``radius x y z``.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numba as nb
import numpy as np


@dataclass(frozen=True)
class SieveCurve:
    """Cumulative mass fraction passing (``passing``) at sieve diameters (``diameters``, m).

    Mass is taken as uniformly distributed in d inside each sieve interval, so the
    number density there is ∝ d⁻³ and the sampled mass fractions reproduce the curve.
    """

    diameters: np.ndarray
    passing: np.ndarray

    def __post_init__(self):
        d, f = np.asarray(self.diameters, float), np.asarray(self.passing, float)
        if d.ndim != 1 or d.shape != f.shape or len(d) < 2:
            raise ValueError("a sieve curve needs >= 2 diameters and as many passing fractions")
        if np.any(np.diff(d) <= 0) or d[0] <= 0:
            raise ValueError(f"sieve diameters must be positive and increasing, got {d}")
        if np.any(np.diff(f) < 0) or f[0] < 0 or abs(f[-1] - 1.0) > 1e-9:
            raise ValueError(f"passing fractions must be non-decreasing from >= 0 to 1, got {f}")
        object.__setattr__(self, "diameters", d)
        object.__setattr__(self, "passing", f)

    def scaled(self, factor):
        """The same curve with every diameter multiplied by ``factor`` (thesis: 4)."""
        return SieveCurve(self.diameters * factor, self.passing)

    def truncated(self, d_min):
        """Drop the fines below ``d_min`` and renormalise the remaining mass to 1."""
        d, f = self.diameters, self.passing
        if not d[0] <= d_min < d[-1]:
            raise ValueError(f"truncation diameter {d_min} outside the curve [{d[0]}, {d[-1]}]")
        f_cut = np.interp(d_min, d, f)
        keep = d > d_min
        d_new = np.concatenate([[d_min], d[keep]])
        f_new = (np.concatenate([[f_cut], f[keep]]) - f_cut) / (1.0 - f_cut)
        return SieveCurve(d_new, f_new)

    def sample_diameters(self, count, rng):
        """Draw ``count`` diameters whose mass distribution follows the curve."""
        a, b = self.diameters[:-1], self.diameters[1:]
        mass_fraction = np.diff(self.passing)
        # number per unit mass in [a, b] with uniform mass density in d: ∫ d⁻³ dd /(b − a)
        number_weight = mass_fraction * 0.5 * (a ** -2 - b ** -2) / (b - a)
        prob = number_weight / number_weight.sum()
        k = rng.choice(len(prob), size=count, p=prob)
        u = rng.random(count)
        # inverse CDF of the pdf ∝ d⁻³ on [a, b]
        return (a[k] ** -2 - u * (a[k] ** -2 - b[k] ** -2)) ** -0.5

    def mass_passing(self, diameters):
        """Mass fraction of ``diameters`` (spheres) finer than each sieve size."""
        d = np.sort(np.asarray(diameters))
        mass = np.cumsum(d ** 3)
        return np.interp(self.diameters, d, mass / mass[-1], left=0.0, right=1.0)


#: The sand of the thesis, App. D.1 (docs/design.md §3.1), in metres.
THESIS_SAND = SieveCurve(
    np.array([0.14, 0.15, 0.3, 0.6, 1.18, 2.36, 4.75, 5.0]) * 1e-3,
    np.array([0.0, 0.0207, 0.0717, 0.2317, 0.647, 0.8803, 0.9899, 1.0]),
)
SIEVE_PRESETS = {"thesis_sand": THESIS_SAND}


def random_cloud(radii, box_min, box_max, seed, max_attempts=200):
    """Place spheres of the given radii at random, without overlap, inside a box.

    Spheres are inserted largest first; each gets up to ``max_attempts`` random
    positions, checked against its neighbours in a cell grid. Returns
    ``(positions, radii)`` of the spheres placed (all of them, or an error if the
    box is too small for the requested count).
    """
    radii = np.sort(np.asarray(radii, float))[::-1].copy()
    lo, hi = np.asarray(box_min, float), np.asarray(box_max, float)
    if np.any(hi - lo <= 2 * radii[0]):
        raise ValueError("the box is smaller than the largest sphere")
    rng = np.random.default_rng(seed)
    inserter = SphereInserter(radii, lo, hi)
    for start in range(0, len(radii), CANDIDATE_BLOCK):  # the same draws as all at once, a block's memory
        block = radii[start:start + CANDIDATE_BLOCK]
        trials = rng.random((len(block), max_attempts, 3))
        span = (hi - lo)[None, None, :] - 2.0 * block[:, None, None]
        if inserter.add(lo[None, None, :] + block[:, None, None] + trials * span) < start + len(block):
            break
    pos, placed = inserter.pos[:inserter.placed], inserter.placed
    if placed < len(radii):
        solid = 4 / 3 * np.pi * np.sum(radii ** 3) / np.prod(hi - lo)
        raise ValueError(f"could place only {placed} of {len(radii)} spheres without overlap "
                         f"(requested solid fraction {solid:.2f}); enlarge the box or lower the count")
    return pos, radii


CANDIDATE_BLOCK = 2048  # spheres whose candidate centres are drawn and tried at once


class SphereInserter:
    """Random sequential addition, block after block: sphere i (``radii`` largest first) goes
    to the first of its candidate centres (inside the box [lo, hi]) that overlaps no sphere
    placed before, checked in a uniform cell grid (cell = largest diameter). :meth:`add` takes
    the candidates of the next spheres, so that a caller draws them a block at a time (the
    memory of one block, not of every sphere's) and gets the placement it would get from all
    of them at once."""

    def __init__(self, radii, lo, hi):
        self.radii = np.ascontiguousarray(radii, float)
        self.lo, self.hi = np.asarray(lo, float), np.asarray(hi, float)
        cell = 2.0 * self.radii[0]
        self.dims = np.array([max(1, int((self.hi[a] - self.lo[a]) / cell)) for a in range(3)], np.int64)
        self.head = -np.ones(int(np.prod(self.dims)), np.int64)
        self.next = -np.ones(len(self.radii), np.int64)
        self.pos = np.zeros((len(self.radii), 3))
        self.placed = 0
        self.failed = False

    def add(self, candidates):
        """Place the next ``len(candidates)`` spheres (``candidates[k]``: the centres to try for
        sphere ``placed + k``, in order); stops at the first sphere none of whose candidates
        fits (``failed``). Returns the number placed so far."""
        if self.failed:
            return self.placed
        count = _insert(self.radii, np.ascontiguousarray(candidates, float), self.placed, self.pos, self.head,
                        self.next, self.lo, self.hi, self.dims)
        self.failed = count < len(candidates)
        self.placed += count
        return self.placed


def insert_spheres(radii, candidates, lo, hi):
    """:class:`SphereInserter` with every sphere's candidates at once; returns (positions,
    number placed)."""
    inserter = SphereInserter(radii, lo, hi)
    placed = inserter.add(candidates)
    return inserter.pos[:placed], placed


@nb.njit(cache=True)
def _insert(radii, candidates, first, pos, head, nxt, lo, hi, dims):
    """Spheres ``first`` … ``first + len(candidates) − 1`` of :class:`SphereInserter`; returns
    how many were placed before the first that did not fit."""
    for k in range(candidates.shape[0]):
        i = first + k
        r = radii[i]
        ok = False
        for t in range(candidates.shape[1]):
            c = np.empty(3)
            ic = np.empty(3, np.int64)
            for a in range(3):
                c[a] = candidates[k, t, a]
                ic[a] = max(0, min(dims[a] - 1, int((c[a] - lo[a]) / (hi[a] - lo[a]) * dims[a])))
            ok = True
            for dx in range(-1, 2):
                for dy in range(-1, 2):
                    for dz in range(-1, 2):
                        jx, jy, jz = ic[0] + dx, ic[1] + dy, ic[2] + dz
                        if jx < 0 or jy < 0 or jz < 0 or jx >= dims[0] or jy >= dims[1] or jz >= dims[2]:
                            continue
                        j = head[(jx * dims[1] + jy) * dims[2] + jz]
                        while j >= 0 and ok:
                            d2 = 0.0
                            for a in range(3):
                                d2 += (c[a] - pos[j, a]) ** 2
                            if d2 < (r + radii[j]) ** 2:
                                ok = False
                            j = nxt[j]
            if ok:
                for a in range(3):
                    pos[i, a] = c[a]
                key = (ic[0] * dims[1] + ic[1]) * dims[2] + ic[2]
                nxt[i] = head[key]
                head[key] = i
                break
        if not ok:
            return k
    return candidates.shape[0]


def save_packing(path, positions, radii, **metadata):
    """Write a packing as ``.npz`` or as text ``x y z r`` (by the file suffix)."""
    path = Path(path)
    if path.suffix == ".npz":
        np.savez(path, positions=positions, radii=radii, **metadata)
    else:
        header = "x y z r  [m]" + "".join(f"\n{k} = {v}" for k, v in metadata.items())
        np.savetxt(path, np.column_stack([positions, radii]), header=header, fmt="%.9e")


def load_packing(path):
    """Read a packing written by :func:`save_packing`, YADE/ESyS text, or a LIGGGHTS dump.

    Returns ``(positions (n, 3), radii (n,))``. Raises ValueError naming the file and
    what is wrong (an empty file, not UTF-8, no spheres, arrays of different lengths, missing columns,
    values that are not finite, radii that are not positive, with the first bad sphere).
    """
    path = Path(path)
    if path.suffix == ".npz":
        if path.stat().st_size == 0:
            raise ValueError(f"{path}: the file is empty (0 bytes); a .npz packing holds 'positions' and 'radii'")
        with np.load(path) as data:
            missing = [k for k in ("positions", "radii") if k not in data]
            if missing:
                raise ValueError(f"{path}: no array {missing[0]!r} (found {sorted(data)})")
            positions, radii = np.asarray(data["positions"], float), np.asarray(data["radii"], float)
        if positions.ndim != 2 or positions.shape[1:] != (3,) or radii.shape != positions.shape[:1]:
            raise ValueError(f"{path}: 'positions' must be (n, 3) and 'radii' (n,); found {positions.shape} "
                             f"and {radii.shape}")
        return _checked(path, positions, radii)
    try:
        text = path.read_text(encoding="utf-8").splitlines()
    except UnicodeDecodeError as exc:
        raise ValueError(f"{path}: not UTF-8 text (byte {exc.start}); a packing is .npz or text") from None
    atoms = [i for i, line in enumerate(text) if line.startswith("ITEM: ATOMS")]
    if atoms:
        cols = text[atoms[0]].split()[2:]
        missing = [c for c in ("x", "y", "z", "radius") if c not in cols]
        if missing:
            raise ValueError(f"{path}: the LIGGGHTS dump has no column {missing[0]!r} (columns: {' '.join(cols)})")
        table = _table(path, text[atoms[0] + 1:], len(cols))
        if "id" in cols:  # a multi-rank LIGGGHTS run writes the atoms in rank order
            table = table[np.argsort(table[:, cols.index("id")], kind="stable")]
        idx = [cols.index(c) for c in ("x", "y", "z", "radius")]
        return _checked(path, table[:, idx[:3]].copy(), table[:, idx[3]].copy())
    rows = [line.split("#")[0] for line in text if line.split("#")[0].strip()]
    table = _table(path, rows, None)
    if table.shape[1] < 4:
        raise ValueError(f"{path}: a text packing needs 4 columns 'x y z r', found {table.shape[1]}")
    return _checked(path, table[:, :3].copy(), table[:, 3].copy())


def _table(path, rows, columns):
    """The numbers of ``rows`` (text lines) as a 2-D array; a ragged or non-numeric row is named."""
    if not rows:
        raise ValueError(f"{path}: no spheres in the file")
    values = []
    for i, row in enumerate(rows):
        try:
            values.append([float(v) for v in row.split()])
        except ValueError:
            raise ValueError(f"{path}: sphere {i + 1} ({row.strip()[:60]!r}) is not a row of numbers") from None
        want = columns or len(values[0])
        if len(values[-1]) != want:
            raise ValueError(f"{path}: sphere {i + 1} has {len(values[-1])} numbers, the first has {want}")
    return np.array(values, dtype=float)


def _checked(path, positions, radii):
    """Refuse non-finite values and radii that are not positive, naming the first such sphere."""
    bad = np.flatnonzero(~np.isfinite(positions).all(axis=1) | ~np.isfinite(radii))
    if bad.size:
        i = bad[0]
        raise ValueError(f"{path}: {bad.size} sphere(s) with a NaN or infinite value (first: sphere {i + 1}, "
                         f"x y z r = {positions[i].tolist()} {radii[i]})")
    bad = np.flatnonzero(radii <= 0)
    if bad.size:
        raise ValueError(f"{path}: {bad.size} sphere(s) with radius <= 0 (first: sphere {bad[0] + 1}, "
                         f"r = {radii[bad[0]]})")
    return positions, radii
