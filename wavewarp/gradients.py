"""Gradients of quasi-static equilibria by implicit differentiation (docs/theory/gradients.md).

At an equilibrium x*(θ) of the shell, F(x*, θ) = 0, so dx*/dθ = H⁻¹ ∂F/∂θ with H = -∂F/∂x the
Hessian of the energy, and an objective J(x*) has dJ/dθ = λ · ∂F/∂θ, H λ = ∇J: one adjoint solve
for every parameter. H is the Newton finish's exact sparse Hessian (wavewarp/newton.py), solved in
the complement of the rigid motions (J is rigid-invariant, ∂F/∂θ has no net force or torque) and
refined on a fourth-order Hessian action; ∂F/∂θ is a central difference of the forces at x* between
two shells whose parameter differs. The objective is taken on the last equilibrium of a run whose
wave does not depend on the shape (the insensitive twin): its concentrations, hence its reference, do
not depend on θ. They do depend on the rest shape, on which that wave runs: a control point's
difference replays the wave on each moved rest shape.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Callable

import numpy as np
import scipy.sparse as sparse
import warp as wp

from .mesh import Mesh
from .newton import NewtonFinish, ShiftedInverse, rigid_modes
from .quasistatic import QuasiStaticWaveRun, initial_values, quasi_static_model

PARAMETERS = ("AC", "AI", "thickness", "young", "mu_v")  # the quasi-static scenes' shell parameters
OBJECTIVES = ("height", "volume", "distance:I,J")  # I, J: control point indices
POLISH_TOL = 1e-11  # residual strain the equilibrium is polished to before the adjoint solve
DIFFERENCE_STEP = 1e-5  # relative step of a parameter's central difference (absolute where it is 0)
REFINEMENTS = 8  # iterative refinement of the adjoint on the Hessian action
ACTION_STEP = 1e-5  # the Hessian action's difference step, in mean edges


class GradientError(ValueError):
    """A gradient that cannot be taken as asked (the message names the fix)."""


def height(mesh, origin) -> Callable:
    """J(x) = distance between the limit points of the control vertex nearest `origin` and of the one
    farthest from it (the rest shape's pole and antipode): (J, ∇J as (V, 3))."""
    distance = np.linalg.norm(mesh.vertices - np.asarray(origin, dtype=np.float64), axis=1)
    return material_distance(mesh, int(np.argmin(distance)), int(np.argmax(distance)))


def material_distance(mesh, first: int, second: int) -> Callable:
    """J(x) = distance between the limit points of control vertices `first` and `second`: (J, ∇J as (V, 3))."""
    rows, cols, vals = mesh.limit_mask_matrix()
    mask = sparse.csr_matrix((vals, (rows, cols)), shape=(mesh.n_vertices, mesh.n_vertices))
    weights = (mask[first] - mask[second]).toarray().ravel()  # the first's limit point less the second's

    def objective(x):
        axis = weights @ x
        value = float(np.linalg.norm(axis))
        return value, np.outer(weights, axis / value)

    return objective


def adjoint(newton: NewtonFinish, x: np.ndarray, gradient: np.ndarray) -> np.ndarray:
    """λ with H(x) λ = ∇J in the complement of the rigid motions (flat, float64): the factorization of
    the Newton finish's Hessian with a tiny shift, refined on the Hessian action (`precise_action`)."""
    rigid = rigid_modes(x)
    g = gradient.ravel() - rigid.T @ (rigid @ gradient.ravel())
    inverse = ShiftedInverse(*newton.hessian(x), None)
    inverse.constrain(rigid)
    lam = inverse.solve(g)
    for _ in range(REFINEMENTS):
        residual = g - precise_action(newton, x, lam)
        residual -= rigid.T @ (rigid @ residual)
        if np.linalg.norm(residual) <= 1e-12 * np.linalg.norm(g):
            break
        lam += inverse.solve(residual)
    return lam


def precise_action(newton: NewtonFinish, x: np.ndarray, v: np.ndarray) -> np.ndarray:
    """H v at x (flat, float64) by the fourth-order central difference of the forces along v, steps of
    ACTION_STEP × the mean edge: the Newton finish's second-order action leaves ~1e-4 of a localized load's
    response (a control point's), this one ~1e-7."""
    step = ACTION_STEP * newton.work.edge_length / max(float(np.abs(v).max()), 1e-300)
    shift = (step * v).reshape(-1, 3)
    f2, f1, m1, m2 = (newton.evaluate(x + k * shift)[1] for k in (2, 1, -1, -2))
    return (f2 - 8.0 * f1 + 8.0 * m1 - m2).ravel() / (12.0 * step)


def equilibrium_gradient(shell_for: Callable, x: np.ndarray, c: np.ndarray, objective: Callable, values: dict,
                         step: float = DIFFERENCE_STEP) -> dict:  # fmt: skip
    """{"objective": J, "gradient": {name: dJ/dθ}, "equilibrium": x*, "residual": ...} at the equilibrium
    near x of the shell under control concentrations c. `shell_for(changes)` gives the shell with the
    parameters in `changes` (a dict) changed; `values` the base values of the parameters to
    differentiate by."""
    base = shell_for({})
    base.forces(x, c)  # sets the active reference
    newton = NewtonFinish(base)
    x, status, residual, _ = newton.run(np.asarray(x, dtype=np.float64), POLISH_TOL, 30)
    if status != "converged":
        raise GradientError(f"the equilibrium could not be polished to a residual strain of {POLISH_TOL:g} (reached "
                            f"{residual:.3g}, {status}): the adjoint needs an equilibrium; relax further first")  # fmt: skip
    value, grad = objective(x)
    lam = adjoint(newton, x, grad)
    gradient = {}
    for name, theta in values.items():
        delta = step * abs(theta) if theta else step
        plus, minus = (shell_for({name: theta + sign * delta}) for sign in (1.0, -1.0))
        for shell in (plus, minus):
            shell.rest_volume = base.rest_volume
        force_rate = (plus.forces(x, c) - minus.forces(x, c)) / (2.0 * delta)
        gradient[name] = float(lam @ force_rate.ravel())
    return {"objective": value, "gradient": gradient, "equilibrium": x, "residual": residual, "adjoint": lam}


def enclosed_volume(shell) -> Callable:
    """J(x) = the volume the limit surface encloses (`shell`, float64): (J, ∇J as (V, 3))."""
    with wp.ScopedDevice(shell.device):
        positions, gradient = (wp.zeros(shell.mesh.n_vertices, dtype=shell.vec3) for _ in range(2))

    def objective(x):
        positions.assign(x)
        shell.volume_gradient_device(positions, gradient)
        return shell.volume(x), gradient.numpy().astype(np.float64)

    return objective


def objective_for(run, name: str) -> Callable:
    """The objective named (OBJECTIVES; "distance:I,J" with control point indices) on `run`'s mesh."""
    if name == "height":
        return height(run.mesh, run.origin)
    if name == "volume":
        p = replace(run.p, dtype="float64")
        return enclosed_volume(quasi_static_model(run.mesh, [p], size=run.size, rule=run.shell.rule,
                                                  device=run.shell.device).shell)  # fmt: skip
    first, second = distance_points(name, run.mesh.n_vertices)
    return material_distance(run.mesh, first, second)


def distance_points(name: str, count: int) -> tuple:
    """(I, J) of the objective "distance:I,J", checked against `count` control points."""
    try:
        kind, indices = name.split(":")
        first, second = (int(i) for i in indices.split(","))
    except ValueError:
        kind = None
    if kind != "distance" or not (0 <= first < count and 0 <= second < count) or first == second:
        raise GradientError(f"--objective {name}: objectives are height, volume and distance:I,J with two different "
                            f"control points I, J between 0 and {count - 1}")  # fmt: skip
    return first, second


def check_differentiable(run, wrt, objective: str = "height", points=()) -> None:
    """Raise GradientError, naming the fix, where `scene_gradient(run, wrt, objective, points)` cannot be taken."""
    unknown = [name for name in wrt if name not in PARAMETERS]
    if unknown or not (len(wrt) or len(points)):
        raise GradientError(f"--wrt {','.join(unknown) or '(nothing)'}: differentiable parameters are "
                            f"{', '.join(PARAMETERS)}")  # fmt: skip
    if not isinstance(run, QuasiStaticWaveRun):
        raise GradientError(f"{getattr(run, 'name', 'this scene')} is not a quasi-static scene: take one of the "
                            "oocyte, wave-guide or buckling scenes; a walker's gradient is walker_gradient's "
                            "(wavewarp/walker_gradients.py, the same `wavewarp grad`)")  # fmt: skip
    if run.p.sensitive:
        raise GradientError("the wave runs on the deforming shell (sensitive=true), so its path depends on the "
                            "parameters and the last equilibrium alone does not give the gradient: --set "
                            "sensitive=false (the wave on the rest shell)")  # fmt: skip
    if run.shell.self_contact is not None:
        raise GradientError("the adjoint uses the Newton finish's Hessian, which leaves self-contact out: --set "
                            "self_contact=false")  # fmt: skip
    if objective not in OBJECTIVES[:2]:
        distance_points(objective, run.mesh.n_vertices)
    control_points(points, run.mesh.n_vertices)
    if getattr(run.p, "coupling", "quasi-static") != "quasi-static":
        raise GradientError("the overdamped shell's last position depends on the path that led to it, not on the "
                            "last concentrations alone: --set coupling=quasi-static (the equilibrium's gradient)")
    if len(points) and run.dt_changes:
        raise GradientError("the shape gradient replays the run's wave on each moved rest shape with the run's "
                            "steps, and this run changed its step on the way: --set adaptive_dt=false or a smaller "
                            "dt")  # fmt: skip


def scene_gradient(run, wrt=(), objective: str = "height", points=()) -> dict:
    """dJ/dθ of a finished quasi-static scene run (`QuasiStaticWaveRun`) at its last equilibrium, for the
    shell parameters `wrt` (names of PARAMETERS) and the objective named (OBJECTIVES); with `points` (control
    point indices of the run's mesh, or "all") also "shape_gradient", dJ/dX̄ (P × 3) of the rest shape, and
    "points"."""
    check_differentiable(run, wrt, objective, points)
    device, rule = run.shell.device, run.shell.rule

    def shell_for(changes):
        p = replace(run.p, dtype="float64", **changes)
        return quasi_static_model(run.mesh, [p], size=run.size, rule=rule, device=device).shell

    x = run.frame()["positions"].astype(np.float64)
    c = run.shell.reference_c.numpy().astype(np.float64)
    values = {name: float(getattr(run.p, name)) for name in wrt}
    result = equilibrium_gradient(shell_for, x, c, objective_for(run, objective), values)
    if len(points):
        chosen = control_points(points, run.mesh.n_vertices)
        result.update(points=chosen, shape_gradient=shape_gradient(run, result, c, chosen))
    return result


def shape_gradient(run, result: dict, c: np.ndarray, points: list, step: float = DIFFERENCE_STEP) -> np.ndarray:
    """dJ/dX̄ (P × 3) of the rest shape's control points `points` at the equilibrium of `result`
    (`equilibrium_gradient`'s): λ · ∂F/∂X̄ by central differences of the forces between two shells whose one
    control coordinate moved by ±δ (δ = step × the control points' RMS radius), each under the concentrations
    its own rest shape's wave reaches (the insensitive wave runs on the rest shape, so c moves with X̄ too)."""
    rest = run.mesh.vertices
    replayed = replayed_wave(run, rest)[1]
    if not np.allclose(replayed, c, rtol=0.0, atol=1e-6 * max(float(np.abs(c).max()), 1e-300)):
        raise GradientError("the run's wave could not be replayed on its rest shape (its concentrations differ by "
                            f"{np.abs(replayed - c).max():.3g}): take the shape gradient on a run from t = 0, not a "
                            "resumed one")  # fmt: skip
    delta = step * control_scale(rest)
    x, lam = result["equilibrium"], result["adjoint"]
    gradient = np.zeros((len(points), 3))
    for k, point in enumerate(points):
        for axis in range(3):
            forces = []
            for sign in (1.0, -1.0):
                moved = rest.copy()
                moved[point, axis] += sign * delta
                shell, concentrations = replayed_wave(run, moved)
                forces.append(shell.forces(x, concentrations))
            gradient[k, axis] = float(lam @ ((forces[0] - forces[1]) / (2.0 * delta)).ravel())
    return gradient


def replayed_wave(run, vertices: np.ndarray) -> tuple:
    """(float64 shell, control concentrations) of the run's scene on the rest shape `vertices` (the run's
    topology) at the run's time: its wave from the same initial values, stepped as the run stepped it."""
    mesh = Mesh(vertices, run.mesh.triangles)
    model = quasi_static_model(mesh, [replace(run.p, dtype="float64")], size=run.size, rule=run.shell.rule,
                               device=run.shell.device)  # fmt: skip
    operator = model.operator()
    c0, v0 = initial_values(operator, run.origin, run.initial, gamma=run.p.gamma, size=run.size)
    wave = model.wave(operator, c0=c0, v0=v0, dt=run.wave.dt)
    chunk = run.coupled.chemistry_steps
    for _ in range(run.wave.steps // chunk):
        wave.advance(chunk)
    return model.shell, wave.concentration().astype(np.float64)


def control_points(points, count: int) -> list:
    """The control points' indices asked for ("all": every one of `count`), checked."""
    chosen = list(range(count)) if isinstance(points, str) and points == "all" else [int(i) for i in points]
    wrong = [i for i in chosen if not 0 <= i < count]
    if wrong or len(set(chosen)) != len(chosen):
        raise GradientError(f"points {wrong or chosen}: give distinct control points between 0 and {count - 1} (the "
                            f"mesh has {count}), or all")  # fmt: skip
    return chosen


def control_scale(vertices: np.ndarray) -> float:
    """The control points' RMS distance from their centroid: the length the shape's steps are relative to."""
    return float(np.sqrt(np.mean(np.sum((vertices - vertices.mean(axis=0)) ** 2, axis=1))))
