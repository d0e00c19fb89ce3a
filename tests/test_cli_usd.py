"""CLI and USD output: files reopen with pxr, errors exit non-zero and leave nothing behind."""

import json
import subprocess
import sys

import numpy as np
import pytest
from pxr import Usd, UsdGeom

from wavewarp import __version__
from wavewarp.cli import main
from wavewarp.mesh import icosphere
from wavewarp.colours import colour_map
from wavewarp.usd import UsdAnimation


def run_cli(*args):
    return subprocess.run([sys.executable, "-m", "wavewarp.cli", *args], capture_output=True, text=True)


def test_version_and_list():
    result = run_cli("--version")
    assert result.returncode == 0 and result.stdout.strip() == f"wavewarp {__version__}"
    assert run_cli("list").returncode == 0


def test_render_writes_a_loop_usd_with_curvature_colours(tmp_path, capsys):
    out = tmp_path / "sphere.usda"
    assert main(["render", "--level", "2", "--size", "2.0", "--out", str(out), "--device", "cpu", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["area"] == pytest.approx(4 * np.pi * 4.0, rel=1e-3)
    stage = Usd.Stage.Open(str(out))
    assert UsdGeom.GetStageUpAxis(stage) == "Z"
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Shell"))
    assert mesh.GetSubdivisionSchemeAttr().Get() == "loop"
    points = np.array(mesh.GetPointsAttr().Get(0))
    assert points.shape == (162, 3)
    curvature = np.array(UsdGeom.PrimvarsAPI(mesh).GetPrimvar("meanCurvature").Get(0))
    np.testing.assert_allclose(curvature, 0.5, rtol=0.05)  # 1/R
    colours = UsdGeom.PrimvarsAPI(mesh).GetPrimvar("displayColor")
    assert colours.GetInterpolation() == "vertex" and len(colours.Get(0)) == 162
    stated = stage.GetRootLayer().customLayerData  # render's explicit scale: 1st to 99th percentile
    np.testing.assert_allclose(list(stated["wavewarp:colourRange"]), np.percentile(curvature, [1, 99]), rtol=1e-6)
    assert stated["wavewarp:colourField"] == "meanCurvature" and "wavewarp:colourPercentiles" not in stated
    assert [p.name for p in tmp_path.iterdir()] == ["sphere.usda"]


@pytest.mark.parametrize(
    "args, message",
    [
        (["--mesh", "missing.obj"], "cannot read mesh file"),
        (["--out", "no/such/folder/x.usd"], "does not exist"),
        (["--out", "x.png"], "must end in .usd"),
        (["--rule", "5"], "quadrature rule"),
    ],
)
def test_render_errors_are_one_line_and_leave_no_file(tmp_path, monkeypatch, capsys, args, message):
    """The command line's own entry point, in this process (`wavewarp` runs the same `main`)."""
    monkeypatch.chdir(tmp_path)
    assert main(["render", "--level", "1", "--device", "cpu", *args]) == 2
    stderr = capsys.readouterr().err
    assert message in stderr and len(stderr.strip().splitlines()) == 1
    assert list(tmp_path.iterdir()) == []


def test_usd_animation_is_atomic_and_keeps_frames_on_interrupt(tmp_path):
    mesh = icosphere(1.0, 1)
    path = tmp_path / "a.usd"
    with pytest.raises(RuntimeError):
        with UsdAnimation(path, mesh.triangles) as usd:
            usd.add_frame(0.0, {"positions": mesh.vertices, "concentration": np.zeros(mesh.n_vertices)})
            raise RuntimeError("crash")
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(KeyboardInterrupt):
        with UsdAnimation(path, mesh.triangles) as usd:
            for k in range(3):
                usd.add_frame(k, {"positions": mesh.vertices * (1 + 0.1 * k), "concentration": np.full(mesh.n_vertices, k / 2)})
            raise KeyboardInterrupt
    stage = Usd.Stage.Open(str(path))
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (0, 2)
    shell = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Shell"))
    np.testing.assert_allclose(np.array(shell.GetPointsAttr().Get(2)), mesh.vertices * 1.2, rtol=1e-6)
    # the frames kept are coloured on their own range: c = 0, 1/2, 1 spans [0, 1]
    assert list(stage.GetRootLayer().customLayerData["wavewarp:colourRange"]) == [0.0, 1.0]
    colours = UsdGeom.PrimvarsAPI(shell).GetPrimvar("displayColor")
    for k in range(3):
        expected = colour_map(np.full(mesh.n_vertices, k / 2), 0.0, 1.0)
        np.testing.assert_allclose(np.array(colours.Get(k)), expected, atol=1e-7)
    assert [p.name for p in tmp_path.iterdir()] == ["a.usd"]


def test_non_finite_frames_are_refused(tmp_path):
    mesh = icosphere(1.0, 1)
    x = mesh.vertices.copy()
    x[3] = np.nan
    with pytest.raises(ValueError, match="non-finite"):
        with UsdAnimation(tmp_path / "b.usd", mesh.triangles) as usd:
            usd.add_frame(0.0, {"positions": x})
    assert list(tmp_path.iterdir()) == []


def test_colour_map_ends():
    colours = colour_map([-1.0, 0.0, 1.0, 2.0], 0.0, 1.0)
    np.testing.assert_allclose(colours[0], colours[1])
    np.testing.assert_allclose(colours[2], colours[3])
    assert colours[2, 0] > 0.9 and colours[1, 2] > 0.3  # viridis: yellow at 1, purple at 0
