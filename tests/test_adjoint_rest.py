"""The rest forms' adjoint pieces (kernels/adjoint_rest.py): the energy rate's derivative in the rest metric and
curvature, against central differences of d·F over shells with moved rest forms, and the rest forms' derivative in
the control points, against central differences of the limit surface's forms (float64)."""

import numpy as np
import pytest
import warp as wp

from wavewarp.device import mat22
from wavewarp.geometry import evaluate
from wavewarp.kernels.adjoint_rest import eval_rest_forms_adjoint
from wavewarp.mesh import icosphere
from wavewarp.shell import Shell

MAT22 = mat22(wp.float64)


def symmetric(rng, count):
    m = rng.standard_normal((count, 2, 2))
    return 0.5 * (m + m.transpose(0, 2, 1))


@pytest.mark.parametrize("model", ["koiter", "bilayer"])
@pytest.mark.parametrize("form", ["metric", "curvature"])
def test_the_rest_forms_rates_match_central_differences_of_the_forces(model, form):
    """−∂Ė/∂ā⁰ and −∂Ė/∂b̄⁰ (= ∂(d·F)/∂·) at every point, along random symmetric moves of the rest forms, against
    d·F of the shell with its rest forms moved by ± δ, at a concentration c that moves the reference (AC, AI)."""
    mesh, rng = icosphere(1.0, level=1), np.random.default_rng(11)
    x = mesh.vertices + 0.02 * rng.standard_normal(mesh.vertices.shape)
    c, direction = rng.uniform(0.0, 1.0, len(x)), rng.standard_normal(x.shape)
    shell = Shell(mesh, 0.05, 3.0, AC=0.3, AI=0.7, volume_penalty=5.0, model=model, dtype="float64", device="cpu")
    points = shell.tables.n_quadrature_points
    hats = {form: wp.zeros(points, dtype=MAT22, device="cpu") for form in ("metric", "curvature")}
    shell.rest_forms_rates_device(shell._set(x, c), wp.array(direction, dtype=wp.vec3d, device="cpu"), hats["metric"],
                                  hats["curvature"])  # fmt: skip
    rest = {"metric": shell.rest_metric, "curvature": shell.rest_curvature}[form]
    base, move, step = rest.numpy().copy(), symmetric(rng, points), 1e-5
    ends = []
    for sign in (1.0, -1.0):
        rest.assign(base + sign * step * move)
        shell._c_host = None  # the reference again from the moved rest forms
        ends.append(np.sum(shell.forces(x, c) * direction))
    rest.assign(base)
    expected = (ends[0] - ends[1]) / (2 * step)
    assert np.sum(hats[form].numpy() * move) == pytest.approx(expected, rel=1e-7)


def test_the_rest_forms_adjoint_matches_central_differences_of_the_limit_surfaces_forms():
    """Σ_q Â_q:ā⁰_q + B̂_q:b̄⁰_q of the limit surface at X, along a random move of the control points."""
    mesh, rng = icosphere(1.0, level=2), np.random.default_rng(2)
    x = mesh.vertices + 0.02 * rng.standard_normal(mesh.vertices.shape)
    shell = Shell(mesh, 0.05, 3.0, dtype="float64", device="cpu")
    tables, points = shell.tables, shell.tables.n_quadrature_points
    metric_hat, curvature_hat = rng.standard_normal((points, 2, 2)), rng.standard_normal((points, 2, 2))
    x_hat = wp.zeros(len(x), dtype=wp.vec3d, device="cpu")
    eval_rest_forms_adjoint(wp.array(x, dtype=wp.vec3d, device="cpu"),
                            *(wp.array(hat, dtype=MAT22, device="cpu") for hat in (metric_hat, curvature_hat)), tables,
                            x_hat)

    def paired(x):
        forms = evaluate(tables, wp.array(x, dtype=wp.vec3d, device="cpu"))
        return np.sum(metric_hat * forms["metric"].numpy()) + np.sum(curvature_hat * forms["curvature"].numpy())

    direction, step = rng.standard_normal(x.shape), 1e-6
    expected = (paired(x + step * direction) - paired(x - step * direction)) / (2 * step)
    assert np.sum(x_hat.numpy() * direction) == pytest.approx(expected, rel=1e-7)
