"""Shipped fold meshes against the analytic M5-like profile (vfcore.mesh.geometry)."""

import math

import numpy as np
import pytest

from vfcore.mesh import geometry as geo
from vfcore.mesh import load_mesh

TARGETS = {"coarse": 172, "medium": 205, "fine": 263}


def _tri_areas(points, tri):
    a, b, c = points[tri[:, 0]], points[tri[:, 1]], points[tri[:, 2]]
    return 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))


def _analytic_area_mm2() -> float:
    """Polygon A-B-T1-M-T4-E plus the two circular segments cut off by the chords T1-M and M-T4."""
    p = geo.profile_points()
    poly = np.array([p["A"], p["B"], p["T1"], p["M"], p["T4"], p["E"]])
    x, z = poly[:, 0], poly[:, 1]
    area = 0.5 * abs(np.dot(x, np.roll(z, -1)) - np.dot(z, np.roll(x, -1)))

    def segment(c, a, b, r):
        th = abs(math.atan2(b[1] - c[1], b[0] - c[0]) - math.atan2(a[1] - c[1], a[0] - c[0]))
        # the profile points really lie on their circles
        assert math.dist(c, a) == pytest.approx(r) and math.dist(c, b) == pytest.approx(r)
        return 0.5 * r * r * (th - math.sin(th))

    area += segment(p["C1"], p["T1"], p["M"], geo.R_MEDIAL)
    area += segment(p["C2"], p["M"], p["T4"], geo.R_SUPERIOR)
    return area


def test_profile_geometry_consistent():
    p = geo.profile_points()
    assert p["M"] == (geo.WIDTH, geo.HEIGHT - geo.R_SUPERIOR)
    # inferior line at 50 degrees from B to T1, tangent to the medial fillet at T1
    (bx, bz), (tx, tz) = p["B"], p["T1"]
    assert math.degrees(math.atan2(tz - bz, tx - bx)) == pytest.approx(geo.SLOPE_DEG)
    cx, cz = p["C1"]
    assert (tx - bx) * (tx - cx) + (tz - bz) * (tz - cz) == pytest.approx(0.0, abs=1e-12)
    assert 0 < p["B"][0] < geo.WIDTH


@pytest.mark.parametrize("name", ["coarse", "medium", "fine"])
def test_shipped_mesh(name):
    m = load_mesh(name)
    nt = m.n_triangles
    assert abs(nt - TARGETS[name]) <= 0.05 * TARGETS[name]
    # all three layers present, each a sizeable part of the section
    counts = np.bincount(m.layer, minlength=3)
    assert counts.size == 3 and np.all(counts >= 5), counts
    # counter-clockwise, non-degenerate triangles
    area = _tri_areas(m.points, m.triangles)
    assert np.all(area > 0)
    assert area.min() > 0.05 * area.mean()
    # every node used; no duplicated nodes
    assert np.array_equal(np.unique(m.triangles), np.arange(m.n_nodes))
    d = np.linalg.norm(m.points[:, None] - m.points[None], axis=-1) + np.eye(m.n_nodes)
    assert d.min() > 1e-5  # m
    # total area = analytic profile area (P1 chords of the arcs lose a little)
    a_mm2 = area.sum() * 1e6
    exact = _analytic_area_mm2()
    assert a_mm2 <= exact * (1 + 1e-9)
    assert a_mm2 == pytest.approx(exact, rel=0.01)
    # bounding box of the section
    mm = m.points * 1e3
    assert mm[:, 0].min() == pytest.approx(0.0, abs=1e-9) and mm[:, 0].max() == pytest.approx(geo.WIDTH, abs=1e-6)
    assert mm[:, 1].min() == pytest.approx(0.0, abs=1e-9) and mm[:, 1].max() == pytest.approx(geo.HEIGHT, abs=1e-6)


@pytest.mark.parametrize("name", ["coarse", "medium", "fine"])
def test_fixed_nodes_and_surface_chain(name):
    m = load_mesh(name)
    mm = m.points * 1e3
    on_wall = (np.abs(mm[:, 0]) < 1e-9) | (np.abs(mm[:, 1]) < 1e-9)
    assert np.array_equal(m.fixed, on_wall)
    assert np.all((mm[m.fixed, 0] == 0.0) | (mm[m.fixed, 1] == 0.0)), "fixed nodes exactly on x=0 or z=0"
    # both fixed lines are meshed (several nodes each)
    assert np.sum(np.abs(mm[:, 0]) < 1e-9) >= 5 and np.sum(np.abs(mm[:, 1]) < 1e-9) >= 3
    s = m.surface
    ps = mm[s]
    p = geo.profile_points()
    # from the base end (B on z = 0) to the superior end (E on the lateral wall)
    assert ps[0] == pytest.approx(p["B"], abs=1e-6)
    assert ps[-1] == pytest.approx(p["E"], abs=1e-6)
    assert np.all(m.fixed[s[[0, -1]]]) and not np.any(m.fixed[s[1:-1]])
    assert np.all(np.diff(ps[:, 1]) >= -1e-9)  # z never decreases along the chain
    # consecutive surface nodes share a boundary edge
    edges = {tuple(sorted(e)) for t in m.triangles for e in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0]))}
    assert all(tuple(sorted((a, b))) in edges for a, b in zip(s[:-1], s[1:]))
    # surface nodes lie on the analytic profile: x <= WIDTH, the most medial one at M
    assert ps[:, 0].max() == pytest.approx(geo.WIDTH, abs=1e-6)
    # surface chain length ~ profile length
    w = m.surface_weights()
    assert w.sum() == pytest.approx(np.linalg.norm(np.diff(m.points[s], axis=0), axis=1).sum())
    # the surface lies in the cover layer
    cover_nodes = np.unique(m.triangles[m.layer == geo.COVER_LAYER])
    assert np.all(np.isin(s, cover_nodes))


def test_regenerate_medium_deterministic_and_equal_to_shipped():
    pytest.importorskip("gmsh")
    d = np.load(geo.__file__.replace("geometry.py", "data/medium.npz"))
    lc = float(d["lc_mm"])
    p1, t1, l1 = geo.build_mesh(lc)
    p2, t2, l2 = geo.build_mesh(lc)
    np.testing.assert_array_equal(p1, p2)
    np.testing.assert_array_equal(t1, t2)
    np.testing.assert_array_equal(l1, l2)
    assert len(t1) == len(d["triangles"])
    np.testing.assert_allclose(p1, d["points_mm"], atol=1e-9)
    np.testing.assert_array_equal(t1, d["triangles"])
