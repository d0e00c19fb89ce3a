"""Gradients of quasi-static equilibria by implicit differentiation (docs/theory/gradients.md).

At an equilibrium x*(θ) of the shell, F(x*, θ) = 0, so dx*/dθ = H⁻¹ ∂F/∂θ with H = -∂F/∂x the
Hessian of the energy, and an objective J(x*) has dJ/dθ = λ · ∂F/∂θ, H λ = ∇J: one adjoint solve
for every parameter. H is the Newton finish's exact sparse Hessian (wavewarp/newton.py), solved in
the complement of the rigid motions (J is rigid-invariant, ∂F/∂θ has no net force or torque) and
refined on the exact Hessian action; ∂F/∂θ is a central difference of the forces at x* between two
shells whose parameter differs. The objective is taken on the last equilibrium of a run whose wave
does not depend on the shape (the insensitive twin): its concentrations, hence its reference, do
not depend on θ.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Callable

import numpy as np
import scipy.sparse as sparse

from .newton import NewtonFinish, ShiftedInverse, rigid_modes
from .quasistatic import QuasiStaticWaveRun, quasi_static_model

PARAMETERS = ("AC", "AI", "thickness", "young", "mu_v")  # the quasi-static scenes' shell parameters
OBJECTIVES = ("height",)
POLISH_TOL = 1e-11  # residual strain the equilibrium is polished to before the adjoint solve
DIFFERENCE_STEP = 1e-5  # relative step of a parameter's central difference (absolute where it is 0)
REFINEMENTS = 8  # iterative refinement of the adjoint on the exact Hessian action


class GradientError(ValueError):
    """A gradient that cannot be taken as asked (the message names the fix)."""


def height(mesh, origin) -> Callable:
    """J(x) = distance between the limit points of the control vertex nearest `origin` and of the one
    farthest from it (the rest shape's pole and antipode): (J, ∇J as (V, 3))."""
    rows, cols, vals = mesh.limit_mask_matrix()
    mask = sparse.csr_matrix((vals, (rows, cols)), shape=(mesh.n_vertices, mesh.n_vertices))
    distance = np.linalg.norm(mesh.vertices - np.asarray(origin, dtype=np.float64), axis=1)
    pole_row = mask[int(np.argmin(distance))] - mask[int(np.argmax(distance))]
    weights = pole_row.toarray().ravel()  # the pole's limit point less the antipode's, per control point

    def objective(x):
        axis = weights @ x
        value = float(np.linalg.norm(axis))
        return value, np.outer(weights, axis / value)

    return objective


def adjoint(newton: NewtonFinish, x: np.ndarray, gradient: np.ndarray) -> np.ndarray:
    """λ with H(x) λ = ∇J in the complement of the rigid motions (flat, float64): the factorization of
    the Newton finish's Hessian with a tiny shift, refined on the exact Hessian action."""
    rigid = rigid_modes(x)
    g = gradient.ravel() - rigid.T @ (rigid @ gradient.ravel())
    inverse = ShiftedInverse(*newton.hessian(x), None)
    inverse.constrain(rigid)
    lam = inverse.solve(g)
    for _ in range(REFINEMENTS):
        residual = g - newton.hessian_action(x, lam)
        residual -= rigid.T @ (rigid @ residual)
        if np.linalg.norm(residual) <= 1e-12 * np.linalg.norm(g):
            break
        lam += inverse.solve(residual)
    return lam


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
    return {"objective": value, "gradient": gradient, "equilibrium": x, "residual": residual}


def check_differentiable(run, wrt, objective: str = "height") -> None:
    """Raise GradientError, naming the fix, where `scene_gradient(run, wrt, objective)` cannot be taken."""
    unknown = [name for name in wrt if name not in PARAMETERS]
    if unknown or not wrt:
        raise GradientError(f"--wrt {','.join(unknown) or '(nothing)'}: differentiable parameters are "
                            f"{', '.join(PARAMETERS)}")  # fmt: skip
    if objective not in OBJECTIVES:
        raise GradientError(f"--objective {objective}: objectives are {', '.join(OBJECTIVES)}")
    if not isinstance(run, QuasiStaticWaveRun):
        raise GradientError(f"{getattr(run, 'name', 'this scene')} is not a quasi-static scene: gradients through the walkers' dynamics are not "
                            "built; take one of the oocyte, wave-guide or buckling scenes")  # fmt: skip
    if run.p.sensitive:
        raise GradientError("the wave runs on the deforming shell (sensitive=true), so its path depends on the "
                            "parameters and the last equilibrium alone does not give the gradient: --set "
                            "sensitive=false (the wave on the rest shell)")  # fmt: skip
    if run.shell.self_contact is not None:
        raise GradientError("the adjoint uses the Newton finish's Hessian, which leaves self-contact out: --set "
                            "self_contact=false")  # fmt: skip


def scene_gradient(run, wrt, objective: str = "height") -> dict:
    """dJ/dθ of a finished quasi-static scene run (`QuasiStaticWaveRun`) at its last equilibrium, for the
    shell parameters `wrt` (names of PARAMETERS) and the objective named (OBJECTIVES)."""
    check_differentiable(run, wrt, objective)
    device, rule = run.shell.device, run.shell.rule

    def shell_for(changes):
        p = replace(run.p, dtype="float64", **changes)
        return quasi_static_model(run.mesh, [p], size=run.size, rule=rule, device=device).shell

    x = run.frame()["positions"].astype(np.float64)
    c = run.shell.reference_c.numpy().astype(np.float64)
    values = {name: float(getattr(run.p, name)) for name in wrt}
    return equilibrium_gradient(shell_for, x, c, height(run.mesh, run.origin), values)
