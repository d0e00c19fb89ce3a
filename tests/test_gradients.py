"""Gradients of quasi-static equilibria (wavewarp/gradients.py, docs/theory/gradients.md) against central
differences of full forward runs, in float64."""

import json

import numpy as np
import pytest

from wavewarp.cli import main
from wavewarp.geometry import limit_positions
from wavewarp.gradients import GradientError, scene_gradient
from wavewarp.mesh import Mesh
from wavewarp.parameters import load_scene, resolve

# a quasi-static starfish at level 2 whose wave runs on the rest shell, relaxed by Newton steps to a residual strain
# of 1e-11
SETTINGS = ["level=2", "t_end=3", "frames=1", "sensitive=false", "dtype=float64", "relax_method=newton",
            "relax_tol=1e-11", "newton_steps=60", "coupling=quasi-static"]  # fmt: skip


def starfish(**changes):
    module = load_scene("starfish")
    p = resolve(module.Parameters, None, SETTINGS + [f"{name}={value if isinstance(value, str) else repr(value)}"
                                                     for name, value in changes.items()])  # fmt: skip
    run = module.build(p, device="cpu", report=lambda message: None)
    for _ in range(run.frames):
        run.advance_frame()
    return run


def height_of(run) -> float:
    """The objective recomputed from the run's own limit points (wavewarp.geometry), independently of the
    gradient's mask rows."""
    points = limit_positions(run.mesh, run.frame()["positions"], device="cpu", dtype="float64")
    distance = np.linalg.norm(run.mesh.vertices - run.origin, axis=1)
    return float(np.linalg.norm(points[np.argmin(distance)] - points[np.argmax(distance)]))


def central_difference(name, value, step=1e-4, **base):
    delta = step * abs(value)
    plus, minus = (starfish(**{**base, name: value + sign * delta}) for sign in (1.0, -1.0))
    return (height_of(plus) - height_of(minus)) / (2 * delta)


@pytest.mark.parametrize("name, base", [("AC", {}), pytest.param("thickness", {}, marks=pytest.mark.slow),
                                        pytest.param("AI", {}, marks=pytest.mark.slow),
                                        # the starfish's μV = 24 holds the volume so tightly that the height moves by
                                        # 7e-5 of itself per unit of ln μV, at the equilibria's own accuracy: a softer one
                                        pytest.param("mu_v", {"mu_v": 0.5}, marks=pytest.mark.slow)])  # fmt: skip
def test_the_gradient_of_the_last_equilibrium_matches_central_differences_of_whole_runs(name, base):
    run = starfish(**base)
    result = scene_gradient(run, [name])
    assert result["objective"] == pytest.approx(height_of(run), rel=1e-9)
    expected = central_difference(name, getattr(run.p, name), **base)
    assert abs(expected) * getattr(run.p, name) > 1e-4 * result["objective"]  # a gradient that matters
    assert result["gradient"][name] == pytest.approx(expected, rel=1e-5)


def volume_of(run) -> float:
    return run.shell.volume(run.frame()["positions"])


def distance_of(run, first=5, second=40) -> float:
    points = limit_positions(run.mesh, run.frame()["positions"], device="cpu", dtype="float64")
    return float(np.linalg.norm(points[first] - points[second]))


@pytest.mark.parametrize("objective, measure", [("volume", volume_of), ("distance:5,40", distance_of)])
def test_other_objectives_match_central_differences_of_whole_runs(objective, measure):
    """The enclosed volume (a softer volume penalty, μV = 0.5, lets it move) and the distance between two
    material points, each recomputed from the runs' own positions."""
    run = starfish(mu_v=0.5)
    result = scene_gradient(run, ["AC"], objective)
    assert result["objective"] == pytest.approx(measure(run), rel=1e-9)
    delta = 1e-4 * run.p.AC
    plus, minus = (measure(starfish(mu_v=0.5, AC=run.p.AC + sign * delta)) for sign in (1.0, -1.0))
    expected = (plus - minus) / (2 * delta)
    assert abs(expected) * run.p.AC > 1e-4 * result["objective"]  # a gradient that matters
    assert result["gradient"]["AC"] == pytest.approx(expected, rel=1e-5)  # measured 2e-9 (volume), 2e-8


def test_the_rest_shapes_gradient_matches_central_differences_of_whole_runs():
    """dJ/dX̄ of two control points (every coordinate) against whole runs from rest meshes with that one
    coordinate moved by ±1e-4 L: their waves, rest metrics and volumes all move with it."""
    run = starfish()
    points = [5, 40]
    result = scene_gradient(run, [], points=points)
    module = load_scene("starfish")
    p = resolve(module.Parameters, None, SETTINGS)
    rest = run.mesh.vertices
    delta = 1e-4 * np.sqrt(np.mean(np.sum((rest - rest.mean(axis=0)) ** 2, axis=1)))
    for k, point in enumerate(points):
        expected = np.zeros(3)
        for axis in range(3):
            heights = []
            for sign in (1.0, -1.0):
                moved = rest.copy()
                moved[point, axis] += sign * delta
                other = module.build(p, mesh=Mesh(moved, run.mesh.triangles), device="cpu", report=lambda m: None)
                for _ in range(other.frames):
                    other.advance_frame()
                heights.append(height_of(other))
            expected[axis] = (heights[0] - heights[1]) / (2 * delta)
        assert np.linalg.norm(expected) > 1e-4  # a gradient that matters (J = 19, L = 27)
        # measured: 4e-7 to 7e-7 of each large component, 1e-6 of the point's norm at most on the 2-core CI CPU; 1.1e-5
        # on an H200 host's CPU (another NumPy and BLAS: the equilibria agree to the relaxation's tolerance only)
        assert np.abs(result["shape_gradient"][k] - expected).max() < 3e-5 * np.linalg.norm(expected)


def test_a_float32_runs_gradient_is_the_float64_runs_to_1e_3():
    """The default dtype: the float32 run's last state, polished on the float64 twin, gives the float64 run's
    parameter and shape gradients (the float32 wave's concentrations are the only difference left)."""
    single, double = (starfish(dtype=dtype) for dtype in ("float32", "float64"))
    results = [scene_gradient(run, ["AC", "thickness"], points=[5]) for run in (single, double)]
    assert results[0]["objective"] == pytest.approx(results[1]["objective"], rel=1e-6)
    for name in ("AC", "thickness"):
        assert results[0]["gradient"][name] == pytest.approx(results[1]["gradient"][name], rel=1e-3)
    difference = np.abs(results[0]["shape_gradient"] - results[1]["shape_gradient"]).max()
    assert difference < 1e-3 * np.linalg.norm(results[1]["shape_gradient"])  # measured: J 1.5e-9, AC 1.2e-8,
    # h 1.2e-7, the shape 3.1e-5 of its norm


def test_the_shape_does_not_depend_on_youngs_modulus_alone():
    """Every quasi-static force scales with Y (μV is in units of Y h / R⁴): only ratios matter, so dJ/dY = 0."""
    run = starfish()
    result = scene_gradient(run, ["young", "AC"])
    scale = result["objective"] / run.p.young
    assert abs(result["gradient"]["young"]) < 1e-7 * scale
    assert abs(result["gradient"]["AC"]) * run.p.AC > 1e-3 * result["objective"]


def test_grad_command_prints_the_objective_and_its_gradient(capsys):
    code = main(["grad", "starfish", "--device", "cpu", "--wrt", "AC,thickness", "--points", "5", "--json",
                 *[item for setting in SETTINGS for item in ("--set", setting)]])  # fmt: skip
    captured = capsys.readouterr()
    assert code == 0, captured.err
    result = json.loads(captured.out)
    direct = scene_gradient(starfish(), ["AC", "thickness"], points=[5])
    assert result["objective"] == pytest.approx(direct["objective"], rel=1e-12)
    for name in ("AC", "thickness"):
        assert result["gradient"][name] == pytest.approx(direct["gradient"][name], rel=1e-9)
    assert result["shape_gradient"]["points"] == [5]
    assert np.asarray(result["shape_gradient"]["gradient"]) == pytest.approx(direct["shape_gradient"], rel=1e-9)


@pytest.mark.parametrize(
    "argv, message",
    [
        (["starfish", "--quick", "--wrt", "AC"], "sensitive=false"),
        (["starfish", "--quick", "--set", "sensitive=false", "--wrt", "radius"], "differentiable parameters are"),
        (["starfish", "--quick", "--set", "sensitive=false", "--wrt", "AC", "--objective", "speed"], "objectives are"),
        (["starfish", "--quick", "--set", "sensitive=false", "--points", "5,99999"], "between 0 and 641"),
        (["starfish", "--quick", "--set", "sensitive=false", "--wrt", "AC", "--objective", "distance:3,3"],
         "two different control points"),
        (["starfish", "--quick", "--set", "sensitive=false", "--wrt", "AC"], "--set coupling=quasi-static"),
    ],
)
def test_grad_refuses_what_it_cannot_differentiate_and_names_the_fix(argv, message, capsys):
    assert main(["grad", *argv, "--device", "cpu"]) == 2
    assert message in capsys.readouterr().err


def test_scene_gradient_needs_a_quasi_static_run():
    with pytest.raises(GradientError, match="not a quasi-static scene"):
        scene_gradient(object(), ["AC"])
