"""Mesh relations against independent oracles: law of cosines, brute-force Procrustes,
similarity transforms, locality, order independence, degenerate meshes."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import require_data

from landmark_graph.mesh import corner_angles, delaunay_mesh
from landmark_graph.mesh_relations import mesh_errors
from relation_metric import se2
from slamrel.formats.landmark_maps import read_map


def test_corner_angles_equal_the_law_of_cosines(rng):
    p = rng.uniform(-10, 10, (80, 2))
    mesh = delaunay_mesh(p)
    ang = corner_angles(p, mesh.triangles)
    a, b, c = (p[mesh.triangles[:, k]] for k in range(3))
    la, lb, lc = np.hypot(*(b - c).T), np.hypot(*(c - a).T), np.hypot(*(a - b).T)  # opposite
    at_a = np.arccos((lb**2 + lc**2 - la**2) / (2 * lb * lc))
    at_b = np.arccos((la**2 + lc**2 - lb**2) / (2 * la * lc))
    np.testing.assert_allclose(ang[:, 0], at_a, atol=1e-9)
    np.testing.assert_allclose(ang[:, 1], at_b, atol=1e-9)
    np.testing.assert_allclose(ang.sum(axis=1), np.pi, atol=1e-12)  # counter-clockwise, all > 0
    # thin flags: smallest angle below 5 degrees, by the same oracle
    np.testing.assert_array_equal(mesh.thin, np.degrees(ang.min(axis=1)) < 5.0)


def _procrustes_angle_brute(p, q):
    """argmin_θ Σ ‖R(θ)(p − p̄) − (q − q̄)‖² by a grid and golden-section refinement."""
    from scipy.optimize import minimize_scalar

    p, q = p - p.mean(axis=0), q - q.mean(axis=0)

    def cost(t):
        r = se2.transform_points(np.array([0.0, 0.0, t]), p)
        return float(((r - q) ** 2).sum())

    grid = np.linspace(-np.pi, np.pi, 721)
    t0 = grid[np.argmin([cost(t) for t in grid])]
    return minimize_scalar(
        cost, bounds=(t0 - 0.01, t0 + 0.01), method="bounded", options={"xatol": 1e-12}
    ).x


def test_triangle_frame_displacement_equals_brute_force(rng):
    ref = rng.uniform(-10, 10, (25, 2))
    est = ref + rng.normal(0, 0.3, ref.shape)
    mesh = delaunay_mesh(ref)
    e = mesh_errors(est, ref, mesh)
    tri_sets = [set(t) for t in mesh.triangles.tolist()]
    for k, (i, j) in enumerate(mesh.edges.tolist()):  # oracle: a loop over edges is fine here
        verts = sorted({v for t in tri_sets if {i, j} <= t for v in t})
        assert len(verts) in (3, 4)
        psi = _procrustes_angle_brute(est[verts], ref[verts])
        d = se2.transform_points(np.array([0.0, 0.0, psi]), (est[j] - est[i])[None])[0]
        assert e.edge_displacement_triangle[k] == pytest.approx(
            np.hypot(*(d - (ref[j] - ref[i]))), abs=1e-7
        )


def test_aligned_displacement_equals_explicit_umeyama_and_is_not_local(rng):
    from relation_metric.alignment import umeyama

    ref = rng.uniform(-10, 10, (30, 2))
    est = se2.transform_points(np.array([4.0, -2.0, 0.9]), ref)
    est[5] += [0.5, 0.2]
    mesh = delaunay_mesh(ref)
    e = mesh_errors(est, ref, mesh)
    al = umeyama(est, ref)
    moved = al.apply(np.column_stack((est, np.zeros(30))))[:, :2]
    i, j = mesh.edges.T
    np.testing.assert_allclose(
        e.edge_displacement_aligned, np.hypot(*((moved[j] - moved[i]) - (ref[j] - ref[i])).T)
    )
    # global mode: the alignment spreads the one misplaced landmark over far-away edges too
    far = ~(mesh.edges == 5).any(axis=1)
    assert e.edge_displacement_aligned[far].max() > 1e-3
    # while the local relations vanish there
    assert e.edge_length[far].max() < 1e-9


def test_locality_of_the_triangle_frame_displacement(rng):
    ref = rng.uniform(-10, 10, (60, 2))
    mesh = delaunay_mesh(ref)
    est = ref.copy()
    k = 11
    est[k] += [0.3, -0.2]
    e = mesh_errors(est, ref, mesh)
    in_tri_with_k = np.zeros(len(mesh.edges), dtype=bool)
    tris_k = mesh.triangles[(mesh.triangles == k).any(axis=1)]
    for t in tris_k.tolist():  # edges of the triangles around k (oracle loop)
        for a, b in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0])):
            in_tri_with_k |= (mesh.edges == sorted((a, b))).all(axis=1)
    # an edge whose triangles include k (as an end or the opposite corner) may change; those
    # are exactly the edges of the triangles around k, and no other edge changes
    neighbourhood = in_tri_with_k
    assert np.all(e.edge_displacement_triangle[~neighbourhood] < 1e-12)
    assert np.all(e.edge_displacement_triangle[(mesh.edges == k).any(axis=1)] > 0)


def test_similarity_gives_proportional_lengths_and_no_angle_error(rng):
    ref = rng.uniform(-10, 10, (50, 2))
    s = 1.03
    est = se2.transform_points(np.array([2.0, 1.0, -0.4]), s * ref)
    mesh = delaunay_mesh(ref)
    e = mesh_errors(est, ref, mesh)
    lengths = np.hypot(*(ref[mesh.edges[:, 1]] - ref[mesh.edges[:, 0]]).T)
    np.testing.assert_allclose(e.edge_length, (s - 1) * lengths, rtol=1e-9)
    assert e.corner_angle.max() < 1e-9
    np.testing.assert_allclose(e.edge_displacement_triangle, (s - 1) * lengths, rtol=1e-9)


def test_displacement_errors_are_independent_of_landmark_order(rng):
    ref = rng.uniform(-10, 10, (40, 2))
    est = ref + rng.normal(0, 0.2, ref.shape)
    perm = rng.permutation(40)
    a = mesh_errors(est, ref, m1 := delaunay_mesh(ref))
    b = mesh_errors(est[perm], ref[perm], m2 := delaunay_mesh(ref[perm]))
    key_a = {tuple(sorted(e)): v for e, v in zip(m1.edges.tolist(), a.edge_displacement_triangle)}
    key_b = {
        tuple(sorted(perm[e].tolist())): v
        for e, v in zip(m2.edges.tolist(), b.edge_displacement_triangle)
    }
    assert key_a.keys() == key_b.keys()
    for k, v in key_a.items():
        assert v == pytest.approx(key_b[k], abs=1e-12)


def test_edges_of_a_collinear_chain_have_lengths_but_no_triangle_frame():
    ref = np.column_stack((np.arange(5.0), 2 * np.arange(5.0)))
    est = ref.copy()
    est[2] += [0.0, 0.1]
    mesh = delaunay_mesh(ref)
    e = mesh_errors(est, ref, mesh)
    assert mesh.collinear and mesh.edges.shape == (4, 2) and e.corner_angle.shape == (0, 3)
    np.testing.assert_allclose(
        e.edge_length, np.abs(np.hypot(*np.diff(est, axis=0).T) - np.sqrt(5.0)), atol=1e-15
    )
    assert np.isnan(e.edge_displacement_triangle).all()


@pytest.mark.realdata
def test_mrclam_scaled_and_displaced():
    ref = read_map(require_data("mrclam", "MRCLAM_Dataset7", "Landmark_Groundtruth.dat"))
    mesh = delaunay_mesh(ref.xy)
    assert mesh.thin.sum() >= 3  # tight clusters: thin triangles, flagged
    lengths = np.hypot(*(ref.xy[mesh.edges[:, 1]] - ref.xy[mesh.edges[:, 0]]).T)
    # 1% scale on the real layout: every edge error is 1% of its length, angles unchanged
    e = mesh_errors(1.01 * ref.xy, ref.xy, mesh)
    np.testing.assert_allclose(e.edge_length, 0.01 * lengths, rtol=1e-9)
    assert e.corner_angle.max() < 1e-9
    # landmark 13 moved 2 cm straight away from landmark 12: that edge grows by 2 cm exactly
    est = ref.xy.copy()
    k12, k13 = int(np.flatnonzero(ref.ids == 12)[0]), int(np.flatnonzero(ref.ids == 13)[0])
    u = (ref.xy[k13] - ref.xy[k12]) / np.hypot(*(ref.xy[k13] - ref.xy[k12]))
    est[k13] += 0.02 * u
    e = mesh_errors(est, ref.xy, mesh)
    edge = np.flatnonzero((np.sort(mesh.edges, axis=1) == sorted((k12, k13))).all(axis=1))
    assert edge.size == 1 and e.edge_length[edge[0]] == pytest.approx(0.02, abs=1e-12)
    touching = (mesh.edges == k13).any(axis=1)
    assert np.all(e.edge_length[~touching] == 0) and np.all(e.edge_length[touching] > 0)


def test_mesh_edges_equal_the_edges_of_the_triangles_and_qhull_neighbours(rng):
    from scipy.spatial import Delaunay

    p = np.round(rng.uniform(0, 20, (300, 2)), 1)  # a coarse grid: duplicates, cocircular sets
    mesh = delaunay_mesh(p)
    got = [tuple(e) for e in mesh.edges.tolist()]
    assert len(got) == len(set(got)) and all(i < j for i, j in got)
    from_triangles = {
        tuple(sorted(e))
        for t in mesh.triangles.tolist()
        for e in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0]))
    }
    indptr, nbr = Delaunay(p).vertex_neighbor_vertices
    from_vnv = {(i, int(j)) for i in range(len(p)) for j in nbr[indptr[i] : indptr[i + 1]] if i < j}
    assert set(got) == from_triangles == from_vnv
    # every dropped duplicate sits exactly on its kept twin and joins no edge
    assert mesh.duplicates.shape[0] > 0
    for kept, dropped in mesh.duplicates.tolist():
        np.testing.assert_array_equal(p[kept], p[dropped])
        assert not (mesh.edges == dropped).any()
    # and no position occurs twice among the vertices used
    used = np.unique(mesh.edges)
    assert np.unique(p[used], axis=0).shape[0] == used.size
    # Euler: E = 3V − 3 − h and T = 2V − 2 − h for a triangulation with h hull vertices
    h = np.unique(Delaunay(p[used]).convex_hull).size
    assert mesh.edges.shape[0] == 3 * used.size - 3 - h
    assert mesh.triangles.shape[0] == 2 * used.size - 2 - h
