"""Numbering for memory locality (docs/theory/geometry.md#numbering-for-memory-locality): `Mesh.reordered` is a pure
renumbering (same surface, same mechanics and chemistry, permuted), applied by the generators,
`load` and the refinement, and it gathers each patch and each warp's patches closer together."""

import numpy as np
import pytest
from meshes import octahedron, random_genus0, torus

import wavewarp.mesh as wm
from wavewarp.geometry import limit_positions, limit_surface, patch_tables
from wavewarp.laplace import LaplaceBeltrami
from wavewarp.mesh import Mesh, cube, hilbert_keys, icosphere, prism
from wavewarp.runs import seeded_noise
from wavewarp.shell import Shell

F64 = dict(device="cpu", dtype="float64")
MESHES = {
    "icosphere": lambda: icosphere(1.0, 2, reorder=False),
    "cube": lambda: cube(2.0, 4, reorder=False),
    "prism": lambda: prism(2.0, 4, reorder=False),
    "irregular": lambda: random_genus0(30, 1).subdivided(1),  # valences 3..9
    "torus": lambda: torus(1.0, 0.4, 12, 8),
}


def shuffled(mesh: Mesh, seed: int = 0) -> Mesh:
    """The mesh under a random numbering: the worst case a file can bring."""
    rng = np.random.default_rng(seed)
    return mesh.permuted(rng.permutation(mesh.n_vertices), rng.permutation(mesh.n_triangles))


@pytest.mark.parametrize("bits", [1, 2, 3, 4])
def test_hilbert_keys_walk_a_grid_from_cell_to_neighbouring_cell(bits):
    n = 2**bits
    cells = np.stack(np.meshgrid(*[np.arange(n)] * 3, indexing="ij"), -1).reshape(-1, 3) + 0.5
    keys = hilbert_keys(cells, bits=bits)
    assert np.array_equal(np.sort(keys), np.arange(n**3))  # one key per cell
    walk = cells[np.argsort(keys)]
    assert np.all(np.abs(np.diff(walk, axis=0)).sum(axis=1) == 1)  # each step to a face neighbour


@pytest.mark.parametrize("keep", [False, True])
@pytest.mark.parametrize("name", list(MESHES))
def test_reordered_is_the_same_mesh_renumbered(name, keep):
    mesh = shuffled(MESHES[name]())
    vertex_order, triangle_order = mesh.reordering(keep_triangle_order=keep)
    new = mesh.reordered(keep_triangle_order=keep)
    assert np.array_equal(np.sort(vertex_order), np.arange(mesh.n_vertices))
    assert np.array_equal(np.sort(triangle_order), np.arange(mesh.n_triangles))
    if keep:
        assert np.array_equal(triangle_order, np.arange(mesh.n_triangles))
    assert np.array_equal(new.vertices, mesh.vertices[vertex_order])
    # every triangle keeps its corners' positions in their order: orientation and patch types too
    assert np.array_equal(new.vertices[new.triangles], mesh.vertices[mesh.triangles[triangle_order]])
    assert np.array_equal(new.valence, mesh.valence[vertex_order])
    Mesh(new.vertices, new.triangles)  # valid (permuted() skips the validation)
    again = new.reordered(keep_triangle_order=keep)
    assert np.array_equal(again.vertices, new.vertices) and np.array_equal(again.triangles, new.triangles)
    # vertices in the order of first use
    _, first = np.unique(new.triangles.reshape(-1), return_index=True)
    assert np.all(np.diff(first) > 0)


def test_permuted_rejects_non_permutations():
    mesh = octahedron()
    with pytest.raises(ValueError, match="vertex_order must be a permutation of 0..5"):
        mesh.permuted([0, 1, 2, 3, 4, 4], np.arange(8))
    with pytest.raises(ValueError, match="triangle_order must be a permutation of 0..7"):
        mesh.permuted(np.arange(6), np.arange(7))


@pytest.mark.parametrize(
    "make", [lambda **k: icosphere(2.0, 3, **k), lambda **k: cube(2.0, 6, **k), lambda **k: prism(2.0, 6, **k)]
)
def test_generators_number_their_meshes_for_locality(make):
    plain, numbered = make(reorder=False), make()
    expected = plain.reordered(keep_triangle_order=True)  # their triangle order is already local
    assert np.array_equal(numbered.vertices, expected.vertices)
    assert np.array_equal(numbered.triangles, expected.triangles)


def test_load_numbers_the_file_for_locality_unless_asked_not_to(tmp_path):
    mesh = shuffled(icosphere(1.0, 2, reorder=False))
    path = tmp_path / "ball.obj"
    wm.save(mesh, path)
    as_stored = wm.load(path, weld=False, reorder=False)
    np.testing.assert_allclose(as_stored.vertices, mesh.vertices, atol=1e-12)  # the file's numbering
    assert np.array_equal(as_stored.triangles, mesh.triangles)
    for weld in (False, True):
        loaded, expected = wm.load(path, weld=weld), wm.load(path, weld=weld, reorder=False).reordered()
        assert np.array_equal(loaded.vertices, expected.vertices)
        assert np.array_equal(loaded.triangles, expected.triangles)


def test_refinement_for_patches_is_numbered_for_locality():
    refined = octahedron().refined_for_patches()
    expected = octahedron().subdivided(1).reordered(keep_triangle_order=True)
    assert np.array_equal(refined.vertices, expected.vertices)
    assert np.array_equal(refined.triangles, expected.triangles)


@pytest.mark.parametrize("name", ["irregular", "cube"])
def test_renumbered_mesh_has_the_same_limit_surface_mechanics_and_chemistry(name, rng):
    """Float64 on the CPU: per-point geometry equal bit for bit (the same control points in the same
    patch order), energy equal and forces, limit points and K c equal up to summation order."""
    mesh = shuffled(MESHES[name]())
    new = mesh.reordered()
    vertex_order, triangle_order = mesh.reordering()
    points = patch_tables(mesh).points_per_triangle

    old_surface, new_surface = limit_surface(mesh, **F64), limit_surface(new, **F64)
    for field in ("points", "normals", "metric", "curvature", "area", "mean_curvature"):
        old_values = getattr(old_surface, field).reshape(mesh.n_triangles, points, -1)
        new_values = getattr(new_surface, field).reshape(new.n_triangles, points, -1)
        assert np.array_equal(new_values, old_values[triangle_order]), field
    assert new_surface.total_area == pytest.approx(old_surface.total_area, rel=1e-14)
    np.testing.assert_allclose(limit_positions(new, **F64), limit_positions(mesh, **F64)[vertex_order], atol=1e-14)

    x = mesh.vertices + 0.02 * rng.normal(size=mesh.vertices.shape)
    c = rng.random(mesh.n_vertices)
    shells = [Shell(m, 0.05, 1e3, AC=0.4, AI=0.7, volume_penalty=3.0, **F64) for m in (mesh, new)]
    energies = [shells[0].energy(x, c), shells[1].energy(x[vertex_order], c[vertex_order])]
    forces = [shells[0].forces(x, c), shells[1].forces(x[vertex_order], c[vertex_order])]
    assert energies[1] == pytest.approx(energies[0], rel=1e-13)
    np.testing.assert_allclose(forces[1], forces[0][vertex_order], atol=1e-12 * np.abs(forces[0]).max())

    operators = [LaplaceBeltrami(m, **F64) for m in (mesh, new)]
    np.testing.assert_allclose(operators[1].apply(c[vertex_order]), operators[0].apply(c)[vertex_order], atol=1e-13)
    np.testing.assert_allclose(operators[1].mass(), operators[0].mass()[vertex_order], rtol=1e-14)


def test_seeded_noise_does_not_depend_on_the_numbering():
    mesh = icosphere(1.0, 2, reorder=False)
    new = mesh.reordered()
    vertex_order, _ = mesh.reordering()
    assert np.array_equal(seeded_noise(new, 1e-3, 5), seeded_noise(mesh, 1e-3, 5)[vertex_order])


def test_reordering_gathers_patches_closer_together():
    """The statistics of docs/theory/geometry.md#numbering-for-memory-locality, on a level-4 icosphere and a shuffled one."""
    plain = icosphere(1.0, 4, reorder=False)
    stats = {name: patch_tables(m).locality() for name, m in
             (("plain", plain), ("numbered", icosphere(1.0, 4)), ("shuffled", shuffled(plain)),
              ("shuffled, reordered", shuffled(plain).reordered()))}  # fmt: skip
    assert stats["numbered"]["span"] < 0.25 * stats["plain"]["span"]
    assert stats["numbered"]["warp_sectors"] < 0.9 * stats["plain"]["warp_sectors"]
    assert stats["numbered"]["block_sectors"] < 0.9 * stats["plain"]["block_sectors"]
    assert stats["shuffled, reordered"]["warp_sectors"] < 0.5 * stats["shuffled"]["warp_sectors"]
    assert stats["shuffled, reordered"]["block_sectors"] < 0.2 * stats["shuffled"]["block_sectors"]
