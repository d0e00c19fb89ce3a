"""The rest shape's gradient in reverse mode (wavewarp/adjoint_shape.py): whole runs from meshes moved along a random
direction against dJ/dX, the masses' adjoint pieces against differences of their forward formulas, and the refusals
(float64)."""

import json
from dataclasses import replace

import numpy as np
import pytest
import warp as wp

from wavewarp.adjoint import WalkAdjoint, walker_adjoint_gradient
from wavewarp.adjoint_shape import mean_edge_gradient
from wavewarp.cli import main
from wavewarp.kernels.adjoint import eval_damping_adjoint
from wavewarp.kernels.adjoint_shape import eval_rigid_motion_mass_share
from wavewarp.mesh import Mesh, icosphere
from wavewarp.parameters import load_scene, resolve
from wavewarp.runs import imperfect, mean_edge
from wavewarp.walker import WalkerRun
from wavewarp.walker_gradients import WalkerGradientError

SPHERE = load_scene("sphere-walker")
# the paper's walker model (tests/test_adjoint.py's PAPER_WALK), a quarter period
PAPER_WALK = ["level=1", "settle=2", "frames=1", "dtype=float64", "mechanics=overdamped", "contact_solve=explicit",
              "sharpness=0.1", "sensitive=false", "drag=60", "AC=0.3", "dt=0.5", "periods=0.25"]  # fmt: skip
COULOMB = ["contact_solve=implicit", "sharpness=inf"]


def quiet(message):
    return None


def shape_difference(p, mesh, options, base, direction, step) -> float:
    """(J(X + δd) - J(X - δd)) / 2δ of whole runs (placed, settled with `base`'s mechanics steps, walked)."""
    ends = []
    for sign in (1.0, -1.0):
        moved = Mesh(mesh.vertices + sign * step * direction, mesh.triangles)
        run = WalkerRun("walker", moved, p, mechanics_dt=base.settle_dt, device="cpu", report=quiet, **options)
        ends.append(WalkAdjoint(run).walk(run.frames * run.steps_per_frame))
    return (ends[0] - ends[1]) / (2.0 * step)


@pytest.mark.parametrize("overrides, noise, step", [
    pytest.param([], 0.0, 1e-5, id="paper"),
    pytest.param([*COULOMB, "sensitive=true"], 1e-2, 1e-6, id="coulomb-sensitive", marks=pytest.mark.slow),
    pytest.param(["drag=0"], 1e-2, 1e-6, id="automatic-drag", marks=pytest.mark.slow),
    pytest.param([*COULOMB, "drag_frame=body", "elongation=1.3"], 0.0, 1e-5, id="body-stretched",
                 marks=pytest.mark.slow),
    pytest.param(["contact=area", "drag=0"], 0.0, 1e-7, id="area-explicit", marks=pytest.mark.slow),
    pytest.param(["contact=area", *COULOMB], 0.0, 1e-7, id="area-coulomb", marks=pytest.mark.slow),
    pytest.param(["contact=area", *COULOMB, "drag_frame=body"], 0.0, 1e-7, id="area-body", marks=pytest.mark.slow)])  # fmt: skip
def test_the_rest_shapes_gradient_matches_central_differences_of_whole_runs_from_moved_meshes(overrides, noise, step):
    """dJ/dX · d against whole runs from X ± δd: the placement, the settling, the rest forms and volume, the pulse's
    width, the wave's rest surface and pulse (insensitive), the masses through every step, the implicit contact and
    the objective, the automatic drag (on a mesh whose vertices' shares of the limit points are not tied: a tie is
    a kink of its max), the stretch, and on the area contact its points' weights dω̄⁰ (the spread of the
    pressures, the responses, the placement, the body frame's friction balance) and the contact area per point a/V
    that k and β are given per. δ is relative to R; the walk's contact switches (a point entering the
    contact) make J piecewise smooth, so the cells near one take a smaller step."""
    p = resolve(SPHERE.Parameters, {}, [*PAPER_WALK, *overrides])
    mesh, options = SPHERE.recipe(p, device="cpu", report=quiet)
    if noise:
        mesh = imperfect(mesh, noise * p.radius, 3)
    run = WalkerRun("walker", mesh, p, device="cpu", report=quiet, **options)
    gradient = WalkAdjoint(run, rest_shape=True).gradient(run.frames * run.steps_per_frame, settle=True)["rest_shape"]
    direction = np.random.default_rng(1).standard_normal(mesh.vertices.shape)
    expected = shape_difference(p, mesh, options, run, direction, step * p.radius)
    assert np.sum(gradient * direction) == pytest.approx(expected, rel=1e-5)


@pytest.mark.slow
def test_the_elongations_gradient_matches_central_differences_of_whole_runs():
    """dJ/ds of the stretch along the wave, from the rest shape's gradient, against whole runs at s ± δ."""
    p = resolve(SPHERE.Parameters, {}, [*PAPER_WALK, "elongation=1.2"])
    mesh, options = SPHERE.recipe(p, device="cpu", report=quiet)
    run = WalkerRun("walker", mesh, p, device="cpu", report=quiet, **options)
    adjoint = WalkAdjoint(run, ["elongation"]).gradient(run.frames * run.steps_per_frame, settle=True)
    ends = []
    for sign in (1.0, -1.0):
        moved = WalkerRun("walker", mesh, replace(p, elongation=1.2 + sign * 1e-5), mechanics_dt=run.settle_dt,
                          device="cpu", report=quiet, **options)  # fmt: skip
        ends.append(WalkAdjoint(moved).walk(moved.frames * moved.steps_per_frame))
    assert adjoint["gradient"]["elongation"] == pytest.approx((ends[0] - ends[1]) / 2e-5, rel=1e-5)


def test_the_rigid_motions_mass_share_matches_central_differences_of_the_damping():
    """ŵ · dt η v_rigid(M) (v_rigid = v̄ + Ω × (x - c), all M-weighted) along a random move of the masses, against the
    kernel's M̂ (the damping's sums A, T as its adjoint leaves them)."""
    rng = np.random.default_rng(7)
    n = 30
    x, v, w = rng.standard_normal((n, 3)), rng.standard_normal((n, 3)), rng.standard_normal((n, 3))
    mass, move, rate = rng.uniform(0.5, 2.0, n), rng.standard_normal(n), 0.3

    def rigid_rows(m):
        total = m.sum()
        c, vbar = m @ x / total, m @ v / total
        r = x - c
        inertia = sum(mi * (ri @ ri * np.eye(3) - np.outer(ri, ri)) for mi, ri in zip(m, r))
        omega = np.linalg.solve(inertia, np.sum(m[:, None] * np.cross(r, v), axis=0))
        return c, vbar, omega

    def paired(m):
        c, vbar, omega = rigid_rows(m)
        return rate * np.sum(w * (vbar + np.cross(omega, x - c)))

    c, vbar, omega = rigid_rows(mass)
    rigid = np.zeros((5, 3))
    rigid[2], rigid[3], rigid[4] = c, vbar, omega
    arrays = {name: wp.array(value, dtype=wp.vec3d, device="cpu")
              for name, value in (("x", x), ("v", v), ("w", w), ("rigid", rigid))}
    sums, moment = wp.zeros(3, dtype=wp.vec3d, device="cpu"), wp.zeros(1, dtype=wp.mat33d, device="cpu")
    x_hat, v_hat = wp.zeros(n, dtype=wp.vec3d, device="cpu"), wp.zeros(n, dtype=wp.vec3d, device="cpu")
    masses, mass_hat = wp.array(mass, dtype=wp.float64, device="cpu"), wp.zeros(n, dtype=wp.float64, device="cpu")
    eval_damping_adjoint(arrays["w"], arrays["x"], arrays["v"], masses, arrays["rigid"], mass.sum(), rate, sums, moment,
                         x_hat, v_hat)  # fmt: skip
    eval_rigid_motion_mass_share(arrays["x"], arrays["v"], arrays["rigid"], sums, mass.sum(), rate, mass_hat)
    step = 1e-6
    expected = (paired(mass + step * move) - paired(mass - step * move)) / (2 * step)
    assert np.sum(mass_hat.numpy() * move) == pytest.approx(expected, rel=1e-7)


def test_the_mean_edges_gradient_matches_central_differences():
    mesh, rng = icosphere(1.0, level=1), np.random.default_rng(3)
    direction, step = rng.standard_normal(mesh.vertices.shape), 1e-6
    ends = [mean_edge(Mesh(mesh.vertices + sign * step * direction, mesh.triangles)) for sign in (1.0, -1.0)]
    assert np.sum(mean_edge_gradient(mesh) * direction) == pytest.approx((ends[0] - ends[1]) / (2 * step), rel=1e-8)


@pytest.mark.parametrize("overrides, message", [
    (["dt=0"], "give the chemistry step a value"),
    (["slope=5", *COULOMB, "drag_frame=body", "contact=point"], "slope=0 or drag_frame=lab")])  # fmt: skip
def test_the_rest_shapes_reverse_mode_refuses_what_it_does_not_cover(overrides, message):
    p = resolve(SPHERE.Parameters, {}, [*PAPER_WALK, *overrides])
    with pytest.raises(WalkerGradientError, match=message):
        walker_adjoint_gradient(SPHERE, p, [], points=[0], device="cpu", report=quiet)


def test_the_rest_shapes_gradient_is_the_whole_runs():
    p = resolve(SPHERE.Parameters, {}, PAPER_WALK)
    with pytest.raises(WalkerGradientError, match="drop --hold-start"):
        walker_adjoint_gradient(SPHERE, p, [], points=[0], hold_start=True, device="cpu", report=quiet)
    mesh, options = SPHERE.recipe(p, device="cpu", report=quiet)
    run = WalkerRun("walker", mesh, p, device="cpu", report=quiet, **options)
    with pytest.raises(WalkerGradientError, match="settle=True"):
        WalkAdjoint(run, rest_shape=True).gradient(2)


@pytest.mark.slow
def test_grad_cli_gives_the_rest_shapes_gradient_by_the_reverse_mode(capsys):
    """`wavewarp grad --method adjoint --points`: the JSON's shape gradient is the whole run's dJ/dX at those points,
    as the Python function gives it (the scene's noise included), with the parameters' gradient beside it."""
    sets = [arg for setting in PAPER_WALK for arg in ("--set", setting)]
    code = main(["grad", "sphere-walker", "--method", "adjoint", "--wrt", "AC", "--points", "0,5", "--json",
                 "--device", "cpu", *sets])  # fmt: skip
    assert code == 0
    answer = json.loads(capsys.readouterr().out)
    p = resolve(SPHERE.Parameters, {}, PAPER_WALK)
    direct = walker_adjoint_gradient(SPHERE, replace(p), ["AC"], points=[0, 5], device="cpu", report=quiet)
    assert answer["shape_gradient"]["points"] == [0, 5]
    np.testing.assert_allclose(answer["shape_gradient"]["gradient"], direct["shape_gradient"], rtol=1e-12)
    assert answer["gradient"]["AC"] == pytest.approx(direct["gradient"]["AC"], rel=1e-12)


def test_the_parameters_gradient_reads_the_same_twice():
    """The rest shape reads the parameters' sums again after the result (the contact area's and the drag's shares):
    the reading must leave them as summed (on the CPU an array's NumPy view is its memory)."""
    p = resolve(SPHERE.Parameters, {}, [*PAPER_WALK, *COULOMB, "contact=area"])
    mesh, options = SPHERE.recipe(p, device="cpu", report=quiet)
    run = WalkerRun("walker", mesh, p, device="cpu", report=quiet, **options)
    adjoint = WalkAdjoint(run, ["stiffness", "contact_damping", "drag"])
    result = adjoint.gradient(run.frames * run.steps_per_frame)
    assert adjoint._named_gradient() == result["gradient"] == adjoint._named_gradient()
