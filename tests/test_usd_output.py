"""USD output read back with pxr: simulated time per time code, the run's one colour scale, the baked surface."""

import h5py
import numpy as np
import pytest
import scipy.sparse
from matplotlib import colormaps
from pxr import Usd, UsdGeom

from wavewarp import cli
from wavewarp.geometry import sample_points
from wavewarp.mesh import Mesh, icosphere
from wavewarp.render import render
from wavewarp.subdivision import loop_subdivide
from wavewarp.trajectory import read_frames
from wavewarp.usd import UsdAnimation

TIMES = [0.0, 0.1, 0.35, 1.0, 2.5]  # non-uniform


def write(path, mesh, fields, positions=None, times=TIMES, **options):
    positions = mesh.vertices if positions is None else positions
    with UsdAnimation(path, mesh.triangles, **options) as usd:
        for time, field in zip(times, fields):
            usd.add_frame(time, {"positions": positions, "concentration": field})
    stage = Usd.Stage.Open(str(path))
    return stage, UsdGeom.Mesh(stage.GetPrimAtPath("/World/Shell"))


def primvar(shell, name, code):
    return np.array(UsdGeom.PrimvarsAPI(shell).GetPrimvar(name).Get(code), dtype=np.float64)


def viridis(values, low, high):
    return colormaps["viridis"](np.clip((np.asarray(values, dtype=np.float64) - low) / (high - low), 0, 1))[:, :3]


def test_time_codes_count_frames_and_the_file_keeps_the_simulated_times(tmp_path):
    mesh = icosphere(1.0, 1)
    stage, _ = write(tmp_path / "t.usda", mesh, [np.zeros(mesh.n_vertices)] * len(TIMES), fps=30.0)
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (0, len(TIMES) - 1)
    assert stage.GetTimeCodesPerSecond() == 30.0
    data = stage.GetRootLayer().customLayerData
    assert list(data["wavewarp:time"]) == TIMES
    assert "time unit" in data["wavewarp:timeUnit"]
    time = stage.GetPrimAtPath("/World").GetAttribute("wavewarp:time")
    assert [time.Get(k) for k in range(len(TIMES))] == TIMES


def ramps(n_vertices):
    """Ramps over the vertices, shifted per frame, and one outlier; multiples of 1/64 (exact in float32)."""
    fields = [np.arange(n_vertices) / 64.0 + k / 4.0 for k in range(len(TIMES))]
    fields[2][7] = 100.0
    return fields


def test_colours_use_the_runs_own_percentile_range(tmp_path):
    mesh = icosphere(1.0, 1)
    fields = ramps(mesh.n_vertices)
    stage, shell = write(tmp_path / "c.usda", mesh, fields)
    low, high = np.percentile(np.concatenate(fields), [0.5, 99.5])
    assert high < 100.0  # the outlier does not set the scale
    data = stage.GetRootLayer().customLayerData
    np.testing.assert_allclose(list(data["wavewarp:colourRange"]), [low, high], rtol=1e-12)
    np.testing.assert_allclose(shell.GetPrim().GetAttribute("wavewarp:colourRange").Get(), [low, high], rtol=1e-12)
    assert list(data["wavewarp:colourPercentiles"]) == [0.5, 99.5]
    assert (data["wavewarp:colourField"], data["wavewarp:colourMap"], data["wavewarp:surface"]) == (
        "concentration", "viridis", "loop")  # fmt: skip
    for code, field in enumerate(fields):
        np.testing.assert_array_equal(primvar(shell, "concentration", code), field)
        np.testing.assert_allclose(primvar(shell, "displayColor", code), viridis(field, low, high), atol=1e-7)


def test_an_explicit_field_range_wins(tmp_path):
    mesh = icosphere(1.0, 1)
    fields = ramps(mesh.n_vertices)
    stage, shell = write(tmp_path / "e.usda", mesh, fields, field_range=(0.25, 0.75))
    data = stage.GetRootLayer().customLayerData
    assert list(data["wavewarp:colourRange"]) == [0.25, 0.75] and "wavewarp:colourPercentiles" not in data
    for code, field in enumerate(fields):
        np.testing.assert_allclose(primvar(shell, "displayColor", code), viridis(field, 0.25, 0.75), atol=1e-7)


def deformed(mesh):
    """Non-uniformly deformed control points and a non-uniform field on them."""
    v = mesh.vertices
    x = v * (1.0 + 0.3 * v[:, [2]]) + 0.1 * np.sin(3.0 * v[:, [1, 2, 0]])
    return x, v[:, 0] + 0.5 * v[:, 1] ** 2


def test_baked_one_level_lies_on_the_limit_surface_at_edge_midpoints_and_vertices(tmp_path):
    mesh = icosphere(1.0, 1)
    x, c = deformed(mesh)
    stage, shell = write(tmp_path / "b.usda", mesh, [c], positions=x, times=[0.0], surface="baked", bake_levels=1)
    assert shell.GetSubdivisionSchemeAttr().Get() == "none"
    assert stage.GetRootLayer().customLayerData["wavewarp:surface"] == "baked 1 level"
    counts = np.array(shell.GetFaceVertexCountsAttr().Get())
    assert len(counts) == 4 * mesh.n_triangles and np.all(counts == 3)
    children = np.array(shell.GetFaceVertexIndicesAttr().Get()).reshape(-1, 4, 3)  # 4 children per triangle
    np.testing.assert_array_equal(children[:, 0, 0], mesh.triangles[:, 0])
    # loop_subdivide's children: (a, m_ab, m_ca), (b, m_bc, m_ab), ...; (v, w) weigh the 2nd and 3rd corner
    where = {(0.0, 0.0): children[:, 0, 0], (0.5, 0.0): children[:, 0, 1], (0.5, 0.5): children[:, 1, 1],
             (0.0, 0.5): children[:, 0, 2]}  # fmt: skip
    points, field = np.array(shell.GetPointsAttr().Get(0), dtype=np.float64), primvar(shell, "concentration", 0)
    field_as_points = np.column_stack([c, np.zeros_like(c), np.zeros_like(c)])
    triangles = np.arange(mesh.n_triangles)
    for parameters, vertex in where.items():
        vw = np.tile(parameters, (mesh.n_triangles, 1))
        np.testing.assert_allclose(points[vertex], sample_points(mesh, triangles, vw, x), atol=1e-6)
        np.testing.assert_allclose(field[vertex], sample_points(mesh, triangles, vw, field_as_points)[:, 0], atol=1e-6)


def limit_mask(mesh):
    rows, cols, vals = mesh.limit_mask_matrix()
    return scipy.sparse.csr_matrix((vals, (rows, cols)), shape=(mesh.n_vertices, mesh.n_vertices))


def test_baked_two_levels_are_the_limit_points_of_the_twice_refined_net(tmp_path):
    mesh = icosphere(1.0, 1)
    x, c = deformed(mesh)
    stage, shell = write(tmp_path / "b2.usdc", mesh, [c], positions=x, times=[0.0], surface="baked", bake_levels=2)
    refined = Mesh(x, mesh.triangles).subdivided(2)
    refined_field = loop_subdivide(*loop_subdivide(c, mesh.triangles))[0]
    indices = np.array(shell.GetFaceVertexIndicesAttr().Get()).reshape(-1, 3)
    assert len(indices) == 16 * mesh.n_triangles
    np.testing.assert_array_equal(indices, refined.triangles)
    points = np.array(shell.GetPointsAttr().Get(0), dtype=np.float64)
    np.testing.assert_allclose(points, limit_mask(refined) @ refined.vertices, atol=1e-6)
    np.testing.assert_allclose(primvar(shell, "concentration", 0), limit_mask(refined) @ refined_field, atol=1e-6)
    assert stage.GetRootLayer().customLayerData["wavewarp:surface"] == "baked 2 levels"


def test_render_passes_the_baked_surface_through(tmp_path):
    out = tmp_path / "sphere.usda"
    render(icosphere(2.0, 2), str(out), device="cpu", surface="baked", bake_levels=1)
    stage = Usd.Stage.Open(str(out))
    shell = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Shell"))
    assert shell.GetSubdivisionSchemeAttr().Get() == "none"
    points = np.array(shell.GetPointsAttr().Get(0))
    assert points.shape == (162 + 480, 3)  # vertices and edge points of the level-2 icosphere
    np.testing.assert_allclose(np.linalg.norm(points, axis=1), 2.0, rtol=5e-3)


@pytest.mark.parametrize("options, message", [({"surface": "smooth"}, "--usd-surface must be loop or baked"),
                                              ({"surface": "baked", "bake_levels": 0}, "--usd-bake-levels")])
def test_bad_surface_options_are_refused_before_any_file(tmp_path, options, message):
    with pytest.raises(ValueError, match=message):
        UsdAnimation(tmp_path / "x.usda", icosphere(1.0, 1).triangles, **options)
    assert list(tmp_path.iterdir()) == []


def test_a_scene_run_writes_its_times_and_colour_range_and_a_baked_surface(tmp_path):
    out = tmp_path / "cube.usda"
    assert cli.main(["run", "cube-waves", "--quick", "--device", "cpu", "--usd-surface", "baked", "--usd-bake-levels",
                     "1", "--out", str(out)]) == 0  # fmt: skip
    frames = read_frames(tmp_path / "cube_trajectory.h5")
    stage = Usd.Stage.Open(str(out))
    shell = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Shell"))
    control = frames[0][1]["positions"]
    assert shell.GetSubdivisionSchemeAttr().Get() == UsdGeom.Tokens.none
    assert len(shell.GetFaceVertexCountsAttr().Get()) == 4 * len(stored_triangles(tmp_path / "cube_trajectory.h5"))
    data = stage.GetRootLayer().customLayerData
    assert list(data["wavewarp:time"]) == pytest.approx([t for t, _ in frames], rel=1e-12)
    assert stage.GetEndTimeCode() == len(frames) - 1 and len(control) < len(shell.GetPointsAttr().Get(0))
    baked = np.concatenate([primvar(shell, "concentration", k) for k in range(len(frames))])
    assert list(data["wavewarp:colourRange"]) == pytest.approx(np.percentile(baked, [0.5, 99.5]), rel=1e-6)


def stored_triangles(path):
    with h5py.File(path, "r") as f:
        return f["mesh"]["triangles"][:]
