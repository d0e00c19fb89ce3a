"""Mesh validation messages, generators, Loop refinement and file I/O (docs/theory/geometry.md, docs/theory/scenes.md)."""

import re

import numpy as np
import pytest
from meshes import loop_reference, octahedron, tetrahedron

from wavewarp import mesh as wm
from wavewarp.geometry import limit_positions
from wavewarp.mesh import Mesh, cube, icosphere, prism


def octahedron_arrays():
    m = octahedron()
    return m.vertices.copy(), m.triangles.astype(np.int64).copy()


@pytest.mark.parametrize(
    "mutate, message",
    [
        (lambda v, t: (v[:, :2], t), r"vertices must have shape \(V, 3\)"),
        (lambda v, t: (v, np.c_[t, t[:, :1]]), "triangulate polygons"),
        (lambda v, t: (np.where(np.arange(6)[:, None] == 2, np.nan, v), t), "vertex 2 has a non-finite"),
        (lambda v, t: (np.where(np.arange(6)[:, None] == 3, np.inf, v), t), "vertex 3 has a non-finite"),
        (lambda v, t: (v, np.where(t == 5, 9, t)), "refers to vertices .* must lie in 0..5"),
        (lambda v, t: (v, np.r_[t[:-1], [[0, 0, 5]]]), "triangle 7 is degenerate: it repeats a vertex"),
        (lambda v, t: (np.r_[v, [[0, 0, 0]]], t), "vertex 6 belongs to no triangle"),
        (lambda v, t: (v, t[:-1]), r"belongs only to triangle .* the mesh is open"),
        (lambda v, t: (v, np.r_[t, t[:1]]), "triangles 0 and 8 are duplicates"),
        (lambda v, t: (v, np.r_[t[:1, ::-1], t[1:]]), "orientations are inconsistent"),
        (lambda v, t: (v, t[:, ::-1]), "oriented inward"),
        (lambda v, t: (v, t[:2]), "at least 4 triangles"),
    ],
)
def test_bad_octahedron_is_rejected_with_the_element_and_the_fix(mutate, message):
    v, t = octahedron_arrays()
    with pytest.raises(ValueError, match=message):
        Mesh(*mutate(v, t))


def test_collinear_triangle_is_degenerate():
    v, t = octahedron_arrays()
    v[4] = 0.5 * (v[0] + v[2])  # triangle 0 = (0, 2, 4) becomes a segment
    with pytest.raises(ValueError, match="triangle 0 .* collinear"):
        Mesh(v, t)


def test_non_manifold_edge_is_rejected():
    v, t = octahedron_arrays()
    extra = np.r_[v, [[2.0, 2.0, 0.3], [2.0, 2.0, -0.3]]]
    fin = np.r_[t, [[2, 0, 6], [0, 2, 7], [0, 7, 6], [2, 6, 7]]]  # a tetrahedron hinged on edge (0, 2)
    with pytest.raises(ValueError, match=r"edge \(.\, .\) is shared by 4 triangles .* non-manifold"):
        Mesh(extra, fin)


def test_pinch_vertex_is_rejected():
    a, b = octahedron(), octahedron()
    vb = b.vertices + [2.0, 0.0, 0.0]  # second octahedron touches the first at vertex 0
    vertices = np.r_[a.vertices, np.delete(vb, 1, axis=0)]
    old = np.arange(6)
    new = np.where(old == 1, 0, np.where(old > 1, old - 1 + 6, old + 6))
    triangles = np.r_[a.triangles, new[b.triangles]]
    with pytest.raises(ValueError, match="vertex 0 joins separate fans .* pinch"):
        Mesh(vertices, triangles)


def test_two_components_are_rejected():
    a = octahedron()
    vertices = np.r_[a.vertices, a.vertices + 5.0]
    triangles = np.r_[a.triangles, a.triangles + 6]
    with pytest.raises(ValueError, match="2 separate components"):
        Mesh(vertices, triangles)


def test_loaded_quads_are_rejected(tmp_path):
    path = tmp_path / "cube.obj"
    corners = [(x, y, z) for x in (0, 1) for y in (0, 1) for z in (0, 1)]
    faces = [(1, 2, 4, 3), (5, 7, 8, 6), (1, 5, 6, 2), (3, 4, 8, 7), (1, 3, 7, 5), (2, 6, 8, 4)]
    path.write_text("".join(f"v {x} {y} {z}\n" for x, y, z in corners) + "".join("f %d %d %d %d\n" % f for f in faces))
    with pytest.raises(ValueError, match="quad cells; wavewarp needs a triangle mesh"):
        wm.load(path)


def test_unreadable_file_names_the_file(tmp_path):
    path = tmp_path / "broken.ply"
    path.write_text("not a mesh")
    with pytest.raises(ValueError, match="cannot read mesh file .*broken.ply"):
        wm.load(path)


@pytest.mark.parametrize("suffix", [".obj", ".ply", ".stl", ".off", ".vtk"])
def test_save_load_round_trip(tmp_path, suffix):
    mesh = icosphere(2.0, 1)
    path = tmp_path / f"sphere{suffix}"
    wm.save(mesh, path)
    loaded = wm.load(path)
    assert loaded.n_triangles == mesh.n_triangles and loaded.n_vertices == mesh.n_vertices
    tol = 1e-6 if suffix == ".stl" else 1e-12  # STL stores float32
    np.testing.assert_allclose(np.sort(loaded.vertices, axis=0), np.sort(mesh.vertices, axis=0), atol=tol)
    assert loaded.volume() == pytest.approx(mesh.volume(), rel=1e-6)
    assert [p.name for p in tmp_path.iterdir()] == [path.name]  # no temporary left behind


def test_save_into_missing_folder_fails_cleanly(tmp_path):
    with pytest.raises((FileNotFoundError, ValueError, OSError), match="missing"):
        wm.save(octahedron(), tmp_path / "missing" / "a.obj")


@pytest.mark.parametrize("level", [0, 1, 2, 3])
def test_icosphere_counts_and_limit_radius(level):
    mesh = icosphere(3.0, level)
    assert mesh.n_triangles == 20 * 4**level
    assert mesh.n_vertices == 10 * 4**level + 2
    limit = limit_positions(mesh, dtype="float64", device="cpu")
    np.testing.assert_allclose(np.linalg.norm(limit, axis=1), 3.0, rtol=1e-13)
    plain = icosphere(3.0, level, limit=False)
    np.testing.assert_allclose(np.linalg.norm(plain.vertices, axis=1), 3.0, rtol=1e-14)


@pytest.mark.parametrize("generator, valences", [(cube, {4, 6, 8}), (prism, {4, 5, 6, 8})])
@pytest.mark.parametrize("divisions", [4, 6])
def test_box_generators_are_symmetric_and_well_shaped(generator, valences, divisions):
    mesh = generator(2.0, divisions)
    assert set(np.unique(mesh.valence)) <= valences
    assert not mesh.needs_refinement
    a, b, c = (mesh.vertices[mesh.triangles[:, k]] for k in range(3))
    lengths = np.linalg.norm(np.stack([b - a, c - b, a - c]), axis=2)
    assert lengths.max() / lengths.min() <= np.sqrt(2) + 1e-12  # right isosceles at worst
    extent = mesh.vertices.max(axis=0) - mesh.vertices.min(axis=0)
    if generator is cube:
        np.testing.assert_allclose(extent, 2.0)
        assert mesh.volume() == pytest.approx(8.0)
    else:
        assert extent[2] == pytest.approx(2.0)
        assert mesh.volume() == pytest.approx(np.sqrt(3) / 4 * 4 * 2)
    np.testing.assert_allclose(mesh.vertices.mean(axis=0), 0.0, atol=1e-12)


@pytest.mark.parametrize("bad", [dict(edge=-1.0), dict(edge=np.nan), dict(divisions=3), dict(divisions=0)])
@pytest.mark.parametrize("generator", [cube, prism])
def test_box_generators_reject_bad_arguments(generator, bad):
    with pytest.raises(ValueError, match="edge must be a positive|divisions must be an even"):
        generator(**bad)


def test_icosphere_rejects_bad_arguments():
    with pytest.raises(ValueError, match="radius must be a positive"):
        icosphere(0.0, 1)
    with pytest.raises(ValueError, match="level must be a non-negative integer"):
        icosphere(1.0, 1.5)


@pytest.mark.parametrize("base", [tetrahedron, octahedron, lambda: icosphere(1.0, 1)])
def test_subdivided_matches_a_plain_loop_implementation(base):
    mesh = base()
    reference_vertices, reference_triangles = loop_reference(mesh.vertices, mesh.triangles)
    refined = mesh.subdivided(1)
    assert refined.n_triangles == 4 * mesh.n_triangles
    # same surface up to vertex numbering: compare the triangles' corner coordinates as sets
    ours = np.sort(np.round(refined.vertices[refined.triangles], 12).reshape(-1, 9), axis=0)
    theirs = np.sort(np.round(reference_vertices[reference_triangles], 12).reshape(-1, 9), axis=0)
    np.testing.assert_allclose(np.sort(refined.vertices, axis=0), np.sort(reference_vertices, axis=0), atol=1e-13)
    assert ours.shape == theirs.shape
    assert mesh.subdivided(0).n_triangles == mesh.n_triangles
    assert mesh.subdivided(2).n_triangles == 16 * mesh.n_triangles


def test_two_extraordinary_vertices_on_a_triangle_point_to_subdivided():
    from wavewarp.geometry import limit_surface

    mesh = octahedron()
    assert mesh.needs_refinement and not mesh.subdivided(1).needs_refinement
    with pytest.raises(ValueError, match=r"touches 3 extraordinary .* Mesh.subdivided\(\)"):
        limit_surface(mesh, device="cpu")
    assert mesh.refined_for_patches().n_triangles == 32


def test_load_errors_name_the_files_own_numbers(tmp_path):
    """An open OBJ whose vertices are shuffled: the error names an edge of the missing triangle and a
    triangle holding it, both in the file's 1-based numbers; plain numbers, no NumPy reprs."""
    mesh = icosphere(1.0, 1)
    order = np.random.default_rng(3).permutation(mesh.n_vertices)  # file vertex k is mesh vertex order[k]
    faces = np.argsort(order)[mesh.triangles] + 1
    missing, faces = faces[7], np.delete(faces, 7, axis=0)
    path = tmp_path / "open.obj"
    path.write_text("".join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in mesh.vertices[order].tolist())
                    + "".join(f"f {a} {b} {c}\n" for a, b, c in faces.tolist()))  # fmt: skip
    with pytest.raises(ValueError, match=r"counted from 1") as error:
        wm.load(path)
    a, b, t = map(int, re.search(r"edge \((\d+), (\d+)\) belongs only to triangle (\d+)", str(error.value)).groups())
    assert {a, b} <= set(missing.tolist()) and {a, b} <= set(faces[t - 1].tolist())
    broken = mesh.vertices.copy()
    broken[5, 1] = np.nan
    with pytest.raises(ValueError, match=r"^vertex 5 has a non-finite coordinate \(-?[\d.]+, nan, -?[\d.]+\)"):
        Mesh(broken, mesh.triangles)
