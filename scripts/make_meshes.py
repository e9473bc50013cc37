"""Regenerate the shipped meshes (vfcore/mesh/data/*.npz) with gmsh.

Targets follow Hadwin et al. (2019), Section 4.1 / Fig. 8: about 172, 205 (default)
and 263 triangles; "xfine" and "xxfine" halve and quarter the fine mesh's size (about 4x and
16x its triangles) for convergence studies (:ref:`model-contact`). The characteristic
length is searched on a grid around each target's and the closest triangle count wins.

    python scripts/make_meshes.py            # every mesh
    python scripts/make_meshes.py xfine      # only the named ones (gmsh versions may triangulate
                                             # differently: regenerate only what you mean to change)
"""

import sys
from pathlib import Path

import numpy as np

from vfcore.mesh.geometry import build_mesh

#: name -> (target triangle count, characteristic lengths searched, mm)
TARGETS = {
    "coarse": (172, np.arange(0.80, 1.20, 0.005)),
    "medium": (205, np.arange(0.80, 1.20, 0.005)),
    "fine": (263, np.arange(0.80, 1.20, 0.005)),
    "xfine": (4 * 263, np.arange(0.38, 0.46, 0.0025)),
    "xxfine": (16 * 263, np.arange(0.17, 0.23, 0.0025)),
}
OUT = Path(__file__).resolve().parents[1] / "vfcore" / "mesh" / "data"


def main(names: list[str]) -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    for name in names or list(TARGETS):
        target, grid = TARGETS[name]
        best = None
        for lc in np.round(grid, 4):
            pts, tri, lay = build_mesh(float(lc))
            err = abs(len(tri) - target)
            if best is None or err < best[0]:
                best = (err, float(lc), pts, tri, lay)
        _, lc, pts, tri, lay = best
        np.savez(OUT / f"{name}.npz", points_mm=pts, triangles=tri, layer=lay, lc_mm=lc)
        print(f"{name}: lc={lc:.4f} mm, {len(tri)} triangles, {len(pts)} nodes, layers={np.bincount(lay)}")


if __name__ == "__main__":
    main(sys.argv[1:])
