"""Limit surface kernels against exact answers (docs/theory/geometry.md, docs/theory/scenes.md): float64 unless stated."""

import numpy as np
import pytest
from meshes import limit_mask_reference, loop_reference, octahedron, random_genus0, tetrahedron, torus

from wavewarp.geometry import limit_positions, limit_surface, sample_points
from wavewarp.mesh import Mesh, cube, icosphere, prism

F64 = dict(dtype="float64")


def perturbed(mesh, rng, amount=0.03):
    return Mesh(mesh.vertices + amount * rng.normal(size=mesh.vertices.shape), mesh.triangles)


@pytest.mark.parametrize(
    "make", [lambda r: random_genus0(40, 1).subdivided(1), lambda r: perturbed(icosphere(1.0, 2), r)]
)
def test_limit_positions_equal_the_closed_form_mask(make, device, rng):
    mesh = make(rng)
    x = mesh.vertices + 0.1 * rng.normal(size=mesh.vertices.shape)
    expected = limit_mask_reference(x, mesh.triangles)
    np.testing.assert_allclose(limit_positions(mesh, x, device=device, **F64), expected, rtol=0, atol=1e-12)


def dyadic_vertices(triangles, levels):
    """(root triangle, (v, w), vertex) for every vertex of `levels` plain Loop refinements,
    following the child order of `loop_reference`."""
    corners = [((0.0, 0.0), (1.0, 0.0), (0.0, 1.0))] * len(triangles)
    roots = list(range(len(triangles)))
    for _ in range(levels):
        new_corners, new_roots = [], []
        for (pa, pb, pc), root in zip(corners, roots):
            mid = lambda p, q: ((p[0] + q[0]) / 2, (p[1] + q[1]) / 2)  # noqa: E731
            ab, bc, ca = mid(pa, pb), mid(pb, pc), mid(pc, pa)
            new_corners += [(pa, ab, ca), (ab, pb, bc), (ca, bc, pc), (ab, bc, ca)]
            new_roots += [root] * 4
        corners, roots = new_corners, new_roots
    return corners, roots


@pytest.mark.parametrize(
    "make",
    [
        lambda: tetrahedron().subdivided(1),  # valence 3
        lambda: octahedron().subdivided(1),  # valence 4
        lambda: icosphere(1.0, 1),  # valence 5
        lambda: random_genus0(16, 3).subdivided(1),  # valences 3..8
    ],
)
def test_limit_surface_agrees_with_repeated_loop_subdivision(make, rng):
    """Sub-vertices of L plain Loop refinements (written in tests/meshes.py) sit at dyadic
    parameters; their closed-form limit points are exact surface points, and the refined
    control points themselves converge to the surface as L grows."""
    mesh = make()
    x = mesh.vertices + 0.05 * rng.normal(size=mesh.vertices.shape)
    vertices, triangles = x, mesh.triangles
    distances = []
    for level in (1, 2, 3):
        vertices, triangles = loop_reference(vertices, triangles)
        corners, roots = dyadic_vertices(mesh.triangles, level)
        limit = limit_mask_reference(vertices, triangles)
        pick = rng.choice(len(triangles), size=min(60, len(triangles)), replace=False)
        root = np.repeat(np.asarray(roots)[pick], 3)
        params = np.asarray(corners)[pick].reshape(-1, 2)
        ids = triangles[pick].reshape(-1)
        ours = sample_points(mesh, root, params, x)
        np.testing.assert_allclose(ours, limit[ids], atol=1e-12)
        distances.append(np.abs(ours - vertices[ids]).max())
    assert distances[1] < distances[0] / 1.8 and distances[2] < distances[1] / 1.8


def test_kernel_points_equal_sampled_points(device, rng):
    mesh = perturbed(random_genus0(20, 5).subdivided(1), rng)
    surface = limit_surface(mesh, rule="6", device=device, **F64)
    expected = sample_points(mesh, surface.triangle, surface.parameters)
    np.testing.assert_allclose(surface.points, expected, atol=1e-12)


def test_differential_geometry_is_consistent(device, rng):
    mesh = perturbed(random_genus0(30, 2).subdivided(1), rng)
    s = limit_surface(mesh, device=device, **F64)
    a1, a2 = s.tangents[:, 0], s.tangents[:, 1]
    np.testing.assert_allclose(np.linalg.norm(s.normals, axis=1), 1.0, atol=1e-13)
    np.testing.assert_allclose(np.einsum("qi,qi->q", s.normals, a1), 0.0, atol=1e-12)
    metric = np.stack([np.einsum("qi,qi->q", a, b) for a in (a1, a2) for b in (a1, a2)], 1).reshape(-1, 2, 2)
    np.testing.assert_allclose(s.metric, metric, atol=1e-12)
    j = np.linalg.norm(np.cross(a1, a2), axis=1)
    np.testing.assert_allclose(s.area, j * 0.5 / 3, rtol=1e-12)  # 3-point rule weights 1/6
    shape = np.linalg.solve(s.metric, s.curvature)  # a^{-1} b
    np.testing.assert_allclose(s.mean_curvature, -0.5 * np.trace(shape, axis1=1, axis2=2), atol=1e-9)
    np.testing.assert_allclose(s.gauss_curvature, np.linalg.det(shape), atol=1e-9)
    assert mesh.volume() > 0 and np.mean(np.einsum("qi,qi->q", s.normals, s.points - s.points.mean(0))) > 0


def icosphere_errors(levels, radius=2.0):
    """Area, mean-curvature (L1 and L2, area-weighted) and radius errors of limit surfaces."""
    rows = []
    for level in levels:
        s = limit_surface(icosphere(radius, level), device="cpu", **F64)
        area_error = abs(s.total_area / (4 * np.pi * radius**2) - 1)
        h_error = np.abs(s.mean_curvature * radius - 1)
        radius_error = np.abs(np.linalg.norm(s.points, axis=1) / radius - 1).max()
        l1, l2 = s.integrate(h_error) / s.total_area, np.sqrt(s.integrate(h_error**2) / s.total_area)
        rows.append((area_error, l1, l2, radius_error))
    return np.array(rows)


def test_icosphere_area_and_mean_curvature_converge():
    """Measured orders (docs/theory/geometry.md): area 2.3, H in L1 2.0, H in L2 1.1, radius 2.2.
    H converges slowly in L2 and not pointwise: Loop surfaces flatten at valence-5 vertices."""
    errors = icosphere_errors([3, 4, 5])
    orders = np.log2(errors[:-1] / errors[1:])
    assert np.all(orders[:, [0, 3]] > 2.0), orders
    assert np.all(orders[:, 1] > 1.5) and np.all(orders[:, 2] > 0.9), orders
    assert errors[-1, 0] < 3e-6 and errors[-1, 1] < 3e-4 and errors[-1, 3] < 1e-6


@pytest.mark.parametrize(
    "make, rule, tolerance",
    [
        (lambda: icosphere(1.0, 2), "3", 5e-3),
        (lambda: icosphere(1.0, 3), "3", 1e-3),
        (lambda: cube(2.0, 4), "3x16", 5e-3),
        (lambda: prism(2.0, 4), "3x16", 5e-3),
        (lambda: cube(2.0, 6), "3x16", 5e-3),
        (lambda: prism(2.0, 6), "12", 5e-3),
    ],
)
def test_gauss_bonnet_on_generated_meshes(make, rule, tolerance):
    s = limit_surface(make(), rule=rule, device="cpu", **F64)
    assert abs(s.integrate(s.gauss_curvature) / (4 * np.pi) - 1) < tolerance


def test_gauss_bonnet_on_random_irregular_meshes_shrinks_under_refinement():
    errors = []
    for seed in range(3):
        mesh = random_genus0(50, seed)
        row = []
        for levels in (1, 3):
            s = limit_surface(mesh.subdivided(levels), device="cpu", **F64)
            row.append(abs(s.integrate(s.gauss_curvature) / (4 * np.pi) - 1))
        errors.append(row)
    errors = np.array(errors)
    assert errors[:, 0].max() < 0.02
    assert errors[:, 1].max() < errors[:, 0].max() / 3


def test_torus_has_zero_total_gauss_curvature():
    s = limit_surface(torus(3.0, 1.0, 24, 12), device="cpu", **F64)
    total = s.integrate(s.gauss_curvature)
    assert abs(total) < 1e-3 * s.integrate(np.abs(s.gauss_curvature))


def test_float32_tracks_float64(device):
    mesh = icosphere(1.0, 3)
    s64 = limit_surface(mesh, device=device, dtype="float64")
    s32 = limit_surface(mesh, device=device, dtype="float32")
    assert s32.points.dtype == np.float64  # returned as float64 NumPy either way
    np.testing.assert_allclose(s32.points, s64.points, atol=1e-6)
    np.testing.assert_allclose(s32.mean_curvature, s64.mean_curvature, atol=2e-3)
    assert abs(s32.total_area / s64.total_area - 1) < 1e-6


def test_device_agrees_with_cpu(device, rng):
    mesh = perturbed(random_genus0(30, 4).subdivided(1), rng)
    on_device = limit_surface(mesh, rule="7", device=device, **F64)
    on_cpu = limit_surface(mesh, rule="7", device="cpu", **F64)
    for field in ("points", "normals", "area", "mean_curvature", "gauss_curvature"):
        np.testing.assert_allclose(getattr(on_device, field), getattr(on_cpu, field), rtol=1e-10, atol=1e-12)


def test_bad_positions_are_named():
    mesh = icosphere(1.0, 1)
    with pytest.raises(ValueError, match=r"x must have shape \(42, 3\)"):
        limit_surface(mesh, np.zeros((41, 3)), device="cpu")
    x = mesh.vertices.copy()
    x[7, 1] = np.nan
    with pytest.raises(ValueError, match=r"x\[7\] .* not finite"):
        limit_positions(mesh, x, device="cpu")
    with pytest.raises(ValueError, match="dtype must be 'float32' or 'float64'"):
        limit_surface(mesh, dtype="float16", device="cpu")
    with pytest.raises(ValueError, match="device 'cuda:7' is not available"):
        limit_surface(mesh, device="cuda:7")
