"""M5-like three-layer vocal-fold section and its gmsh triangulation.

Coordinates in mm: x medial-lateral (x = 0 the fixed lateral wall, x grows towards the
midline), z inferior-superior (z = 0 the fixed flat base). Profile (:ref:`model`):

* flat base from (0, 0) to (b, 0), fixed;
* inferior surface rising at 50 degrees from (b, 0);
* medial surface: a convex fillet of radius 5.2 mm tangent to the inferior line and a
  fillet of radius 1.0 mm tangent to the superior surface; the two fillets meet at the
  single most-medial point (8.4, 9.51) -- ``b`` is chosen so that they do;
* flat superior surface z = 10.51 back to the lateral wall, which is fixed.

Layers: cover 1.0 mm thick along the whole free surface, ligament a 0.6-mm band under
the cover on the medial side (under the 5.2-mm fillet), body elsewhere.

gmsh is needed only to regenerate the shipped meshes (``scripts/make_meshes.py``).
"""

from __future__ import annotations

import math

import numpy as np

WIDTH = 8.4  # mm, medial-lateral extent
HEIGHT = 10.51  # mm, inferior-superior extent
SLOPE_DEG = 50.0  # inferior surface angle
R_MEDIAL = 5.2  # mm, lower medial fillet
R_SUPERIOR = 1.0  # mm, upper medial fillet
COVER = 1.0  # mm, cover thickness
LIGAMENT = 0.6  # mm, ligament thickness

BODY, LIGAMENT_LAYER, COVER_LAYER = 0, 1, 2
LAYER_NAMES = ("body", "ligament", "cover")


def profile_points() -> dict[str, tuple[float, float]]:
    """Key points of the profile and the layer boundaries (mm)."""
    s, c = math.sin(math.radians(SLOPE_DEG)), math.cos(math.radians(SLOPE_DEG))
    turn = math.radians(90.0 - SLOPE_DEG)  # angle between inferior line and vertical
    z_medial = HEIGHT - R_SUPERIOR  # height of the most-medial point
    z_corner = z_medial - R_MEDIAL * math.tan(turn / 2)
    b = WIDTH - z_corner / math.tan(math.radians(SLOPE_DEG))
    c1 = (WIDTH - R_MEDIAL, z_medial)  # centre of the medial fillet
    c2 = (WIDTH - R_SUPERIOR, z_medial)  # centre of the superior fillet
    ang = -turn  # direction centre -> tangent point on inferior line

    def on_c1(r):
        return (c1[0] + r * math.cos(ang), c1[1] + r * math.sin(ang))

    pts = {
        "A": (0.0, 0.0),
        "B": (b, 0.0),
        "T1": on_c1(R_MEDIAL),
        "M": (WIDTH, z_medial),
        "T4": (c2[0], HEIGHT),
        "E": (0.0, HEIGHT),
        "C1": c1,
        "C2": c2,
        "Bp": (b - COVER / s, 0.0),
        "T1p": on_c1(R_MEDIAL - COVER),
        "Ep": (0.0, HEIGHT - COVER),
        "Lt": (WIDTH - COVER - LIGAMENT, z_medial),
        "L1": on_c1(R_MEDIAL - COVER - LIGAMENT),
    }
    # the cover's inner boundary meets the superior fillet centre because R_SUPERIOR == COVER
    assert abs(R_SUPERIOR - COVER) < 1e-12
    del c
    return pts


def build_mesh(lc: float, algorithm: int = 6) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Triangulate the section with gmsh at characteristic length ``lc`` (mm).

    Returns (points (n, 2) mm, triangles (nt, 3) int, layer (nt,) int).
    """
    import gmsh

    p = profile_points()
    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("m5")
        geo = gmsh.model.geo
        tag = {k: geo.addPoint(x, z, 0.0, lc) for k, (x, z) in p.items()}
        L, Arc = geo.addLine, geo.addCircleArc
        c = {
            "base_in": L(tag["A"], tag["Bp"]),
            "base_out": L(tag["Bp"], tag["B"]),
            "inferior": L(tag["B"], tag["T1"]),
            "medial": Arc(tag["T1"], tag["C1"], tag["M"]),
            "fillet": Arc(tag["M"], tag["C2"], tag["T4"]),
            "superior": L(tag["T4"], tag["E"]),
            "wall_up": L(tag["E"], tag["Ep"]),
            "wall_lo": L(tag["Ep"], tag["A"]),
            "cov_inf": L(tag["Bp"], tag["T1p"]),
            "cov_arc": Arc(tag["T1p"], tag["C1"], tag["C2"]),
            "lig_top": L(tag["C2"], tag["Lt"]),
            "cov_sup": L(tag["Lt"], tag["Ep"]),
            "lig_arc": Arc(tag["Lt"], tag["C1"], tag["L1"]),
            "lig_inf": L(tag["L1"], tag["T1p"]),
        }
        cover = geo.addPlaneSurface(
            [
                geo.addCurveLoop(
                    [
                        c["inferior"],
                        c["medial"],
                        c["fillet"],
                        c["superior"],
                        c["wall_up"],
                        -c["cov_sup"],
                        -c["lig_top"],
                        -c["cov_arc"],
                        -c["cov_inf"],
                        c["base_out"],
                    ]
                )
            ]
        )
        lig = geo.addPlaneSurface([geo.addCurveLoop([c["cov_arc"], c["lig_top"], c["lig_arc"], c["lig_inf"]])])
        body = geo.addPlaneSurface(
            [geo.addCurveLoop([c["base_in"], c["cov_inf"], -c["lig_inf"], -c["lig_arc"], c["cov_sup"], c["wall_lo"]])]
        )
        geo.synchronize()
        for name, s in (("body", body), ("ligament", lig), ("cover", cover)):
            gmsh.model.addPhysicalGroup(2, [s], name=name)
        gmsh.option.setNumber("Mesh.Algorithm", algorithm)
        gmsh.option.setNumber("Mesh.MeshSizeMin", lc)
        gmsh.option.setNumber("Mesh.MeshSizeMax", lc)
        gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
        gmsh.model.mesh.generate(2)
        node_tags, coords, _ = gmsh.model.mesh.getNodes()
        xy = coords.reshape(-1, 3)[:, :2]
        index = {int(t): i for i, t in enumerate(node_tags)}
        tris, layers = [], []
        for layer, s in ((BODY, body), (LIGAMENT_LAYER, lig), (COVER_LAYER, cover)):
            etypes, _, enodes = gmsh.model.mesh.getElements(2, s)
            for et, en in zip(etypes, enodes):
                if et != 2:
                    raise RuntimeError(f"unexpected gmsh element type {et}")
                t = np.array([index[int(k)] for k in en], dtype=np.int64).reshape(-1, 3)
                tris.append(t)
                layers.append(np.full(len(t), layer, dtype=np.int64))
    finally:
        gmsh.finalize()
    tri = np.concatenate(tris)
    lay = np.concatenate(layers)
    used = np.unique(tri)
    remap = -np.ones(len(xy), dtype=np.int64)
    remap[used] = np.arange(used.size)
    pts = xy[used]
    tri = remap[tri]
    # counter-clockwise orientation
    a, b_, c_ = pts[tri[:, 0]], pts[tri[:, 1]], pts[tri[:, 2]]
    area2 = (b_[:, 0] - a[:, 0]) * (c_[:, 1] - a[:, 1]) - (b_[:, 1] - a[:, 1]) * (c_[:, 0] - a[:, 0])
    flip = area2 < 0
    tri[flip] = tri[flip][:, [0, 2, 1]]
    return pts, tri, lay
