"""Shipped vocal-fold meshes and their boundary topology (SI units: metres)."""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from .geometry import LAYER_NAMES

DATA = Path(__file__).resolve().parent / "data"


@dataclass(frozen=True)
class FoldMesh:
    """A triangulated fold section.

    Attributes
    ----------
    points : (n, 2) node coordinates, m (x medial-lateral, z inferior-superior).
    triangles : (nt, 3) counter-clockwise node indices.
    layer : (nt,) 0 body, 1 ligament, 2 cover.
    fixed : (n,) bool, nodes on the lateral wall (x = 0) or the base (z = 0).
    surface : (m,) free-surface node indices ordered from inferior (airway inlet) to superior.
    name : mesh name.
    """

    points: np.ndarray
    triangles: np.ndarray
    layer: np.ndarray
    fixed: np.ndarray
    surface: np.ndarray
    name: str = ""

    @property
    def n_nodes(self) -> int:
        return len(self.points)

    @property
    def n_triangles(self) -> int:
        return len(self.triangles)

    def surface_weights(self) -> np.ndarray:
        """(m,) edge-length share of each surface node (half of each adjacent edge), m."""
        p = self.points[self.surface]
        seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
        w = np.zeros(len(self.surface))
        w[:-1] += 0.5 * seg
        w[1:] += 0.5 * seg
        return w


def _boundary_chain(points: np.ndarray, triangles: np.ndarray, fixed: np.ndarray) -> np.ndarray:
    """Free-surface nodes ordered from the inferior end (on the base) to the superior end."""
    edges = np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]]), axis=1)
    uniq, counts = np.unique(edges, axis=0, return_counts=True)
    bnd = uniq[counts == 1]
    # free edges: not both ends fixed
    free = bnd[~(fixed[bnd[:, 0]] & fixed[bnd[:, 1]])]
    adj: dict[int, list[int]] = {}
    for a, b in free:
        adj.setdefault(int(a), []).append(int(b))
        adj.setdefault(int(b), []).append(int(a))
    ends = [k for k, v in adj.items() if len(v) == 1]
    if len(ends) != 2:
        raise ValueError(f"free surface is not a single open chain (ends: {ends})")
    start = min(ends, key=lambda k: points[k, 1])  # the end on the base (lowest z)
    chain, prev = [start], -1
    while True:
        nxt = [k for k in adj[chain[-1]] if k != prev]
        if not nxt:
            break
        prev = chain[-1]
        chain.append(nxt[0])
    if len(chain) != len(adj):
        raise ValueError("free surface chain is broken")
    return np.array(chain, dtype=np.int64)


def make_fold_mesh(points_mm: np.ndarray, triangles: np.ndarray, layer: np.ndarray, name: str = "") -> FoldMesh:
    """Build a FoldMesh from coordinates in mm (fixed boundary: x = 0 or z = 0)."""
    pts = np.asarray(points_mm, dtype=float) * 1e-3
    tol = 1e-9
    fixed = (np.abs(pts[:, 0]) < tol) | (np.abs(pts[:, 1]) < tol)
    surface = _boundary_chain(pts, triangles, fixed)
    return FoldMesh(
        points=pts,
        triangles=np.asarray(triangles, dtype=np.int64),
        layer=np.asarray(layer, dtype=np.int64),
        fixed=fixed,
        surface=surface,
        name=name,
    )


@lru_cache(maxsize=8)
def load_mesh(name: str = "medium") -> FoldMesh:
    """Load a shipped mesh: "coarse" (~172 triangles), "medium" (~205), "fine" (~263), "xfine" (~1050), "xxfine" (~4190)."""
    path = DATA / f"{name}.npz"
    if not path.exists():
        raise ValueError(f"unknown mesh {name!r}; shipped: {sorted(p.stem for p in DATA.glob('*.npz'))}")
    d = np.load(path)
    return make_fold_mesh(d["points_mm"], d["triangles"], d["layer"], name=name)


__all__ = ["FoldMesh", "load_mesh", "make_fold_mesh", "LAYER_NAMES"]
