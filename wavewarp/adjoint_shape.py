"""The rest shape's gradient in reverse mode (docs/theory/gradients.md, "The rest shape"): a mixin of `WalkAdjoint`
(wavewarp/adjoint.py) that gathers, over a whole run, every way the control points X of the walker's mesh reach J.

The placed mesh is X stretched along x by the elongation and lowered onto the ground: x⁰ = s ∘ X + (lift - depth) ẑ.
From it come the settling's start (x̂⁰ of the settling's adjoint), the rest forms and the rest volume (their adjoints
taken to the control points), the pulse's width (σ = 1.5 × the mean edge / R, where automatic), the insensitive
wave's rest surface and pulse, and the masses M_J = ρ ∫ N_J dω̄⁰. The masses' adjoint M̂ gathers the steps' F/M,
the inertial damping's rigid-body motion, the implicit contact's M⁻¹ (kernels/adjoint_shape.py), the objective's
mass-weighted centre, the automatic drag ζ = 2β max_J (Lᵀ1)_J / M_J and the placement's weight; it reaches the
control points as the lumped mass's derivative (kernels/adjoint_wave.py `operator_position_adjoint_kernel` with m =
ρM̂). The placement: lift - depth moves by -Σ pen_i dz_i / Σ pen - dW / (2k Σ pen) (the lowest point's own move
cancels), z_i the limit points' heights, pen_i their depths below the ground, W = ρ g × the limit surface's area.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sparse
import warp as wp

from .geometry import limit_positions
from .kernels.adjoint_rest import eval_rest_forms_adjoint
from .kernels.adjoint_shape import eval_inverse_mass_share, eval_rigid_motion_mass_share
from .kernels.adjoint_wave import eval_operator_position_adjoint
from .laplace import LaplaceBeltrami
from .walker_gradients import WalkerGradientError

AREA_RULE = "3"  # the quadrature of the placement's weight (walker.py `place_walker`: the limit surface's area)


def check_rest_shape(p) -> None:
    """Raise WalkerGradientError, naming the fix, where the reverse mode does not give a walker's rest-shape gradient."""
    if p.contact != "point":
        raise WalkerGradientError("the rest shape's reverse-mode gradient covers the point contact (the paper's): "
                                  "--set contact=point, or take central differences (--method differences)")  # fmt: skip
    if p.dt == 0:
        raise WalkerGradientError("dt = auto follows the rest surface's stability bound, which the rest shape moves: "
                                  "give the chemistry step a value (--set dt=0.5)")  # fmt: skip
    if p.slope != 0 and p.drag_frame == "body":
        raise WalkerGradientError("in the body frame on a slope the weight's pull enters the friction balance: the "
                                  "rest shape's reverse-mode gradient needs slope=0 or drag_frame=lab")  # fmt: skip


def mean_edge_gradient(mesh) -> np.ndarray:
    """∂(mean edge length)/∂x (V × 3) of `mesh` at its vertices."""
    edges = mesh.edges
    vectors = mesh.vertices[edges[:, 0]] - mesh.vertices[edges[:, 1]]
    units = vectors / np.linalg.norm(vectors, axis=1)[:, None] / len(edges)
    gradient = np.zeros_like(mesh.vertices)
    np.add.at(gradient, edges[:, 0], units)
    np.add.at(gradient, edges[:, 1], -units)
    return gradient


class RestShapeAdjoint:
    """The masses' adjoint through the steps and the sum to the control points; the host class provides the run, the
    shell, the walk's solver, the scratch arrays, `_contacts` and the rest forms' and volume's adjoints."""

    def _mass_share(self, solver, x, v, dt: float) -> None:
        """M̂ += a step's share (module docstring): F/M through the velocity's adjoint ŵ (the predictor's, v̂*, with
        the implicit contact), and the inertial damping's rigid-body motion (the damping's sums as its adjoint left
        them). The implicit contact's own share is taken in its backward pass."""
        s, overdamped = self._scratch, solver is self.solver
        w_hat = s["v_star_hat"] if solver.implicit else s["w_hat"]
        scale = 1.0 / solver.drag if overdamped else dt
        eval_inverse_mass_share(w_hat, solver.step_forces(x, v), solver.inverse_mass, scale, self._mass_hat)
        if not overdamped and solver.damping > 0:
            eval_rigid_motion_mass_share(x, v, solver.rigid_motion(x, v), self._damping_sums, solver.total_mass,
                                         dt * solver.damping, self._mass_hat)  # fmt: skip

    def _rest_shape_gradient(self, x_start: np.ndarray, x_end: np.ndarray, placement_hat: np.ndarray,
                             result: dict) -> np.ndarray:  # fmt: skip
        """dJ/dX (V × 3) of the whole run at the control points of the walker's mesh (before its stretch), from
        dJ/dx⁰ of the placed mesh (`placement_hat`), the walk's start and end, and the run's other shares in
        `result` (module docstring)."""
        run, p, shell = self.run, self.run.p, self.shell
        mass, total = self.dynamics.mass, self.dynamics.total_mass
        mass_hat = self._mass_hat.numpy().astype(np.float64)
        forward = np.asarray(run.forward, dtype=np.float64)

        def offsets(x):
            return (x - mass @ x / total) @ forward

        mass_hat += (offsets(x_end) - offsets(x_start)) / (total * run.radius)  # J's mass-weighted centres
        if p.drag == 0:  # ζ = 2β max_J (Lᵀ1)_J / M_J
            column_sums = self.solver.limit_column_sums()
            top = int(np.argmax(column_sums / mass))
            mass_hat[top] -= self.solver.drag / mass[top] * self._drag_gradient()
        weight_hat = self._placement_share(placement_hat)
        x_hat = placement_hat.copy()
        rest = run.mesh.vertices
        density = run.model.density
        with wp.ScopedDevice(shell.device):
            rest_x, out = wp.array(rest, dtype=wp.vec3d), wp.zeros(len(rest), dtype=wp.vec3d)
            lumped = LaplaceBeltrami(run.mesh, rule=shell.rule, device=shell.device, dtype="float64")
            zeros = wp.zeros(len(rest), dtype=wp.float64)
            eval_operator_position_adjoint(rest_x, zeros, zeros, wp.array(density * mass_hat, dtype=wp.float64), 0.0,
                                           0.0, lumped.tables, lumped.j_floor, out)  # fmt: skip
            area = lumped if shell.rule == AREA_RULE else LaplaceBeltrami(run.mesh, rule=AREA_RULE, device=shell.device,
                                                                          dtype="float64")  # fmt: skip
            eval_operator_position_adjoint(rest_x, zeros, zeros, wp.full(len(rest), weight_hat * density * run.model.gravity,
                                                                         dtype=wp.float64),
                                           0.0, 0.0, area.tables, area.j_floor, out)  # fmt: skip
            eval_rest_forms_adjoint(rest_x, *self._rest_forms_hat, shell.tables, out)
            x_hat += out.numpy()
            if shell.has_volume:
                volume = wp.zeros(len(rest), dtype=wp.vec3d)
                shell.volume_gradient_device(rest_x, volume)
                x_hat += result["rest_volume"] * volume.numpy()
        if p.width == 0:  # σ = 1.5 × the mean edge / R
            x_hat += result["pulse_sigma"] * 1.5 / run.radius * mean_edge_gradient(run.mesh)
        if not self.sensitive:
            x_hat += result["rest_operator"] + result["rest_pulse"]
        return x_hat * np.array([p.elongation, 1.0, 1.0])

    def _placement_share(self, placement_hat: np.ndarray) -> float:
        """x̂ of the placed mesh's lowering (lift - depth) taken to the limit points' heights, added to `placement_hat`
        in place; returns Ŵ, the placement weight's adjoint (module docstring)."""
        mesh, ground = self.run.mesh, self.solver.ground
        lowering_hat = float(np.sum(placement_hat[:, 2]))
        z = limit_positions(mesh, device="cpu", dtype="float64")[:, 2]
        rows, cols, vals = mesh.limit_mask_matrix()
        limit = sparse.csr_matrix((vals, (rows, cols)), shape=(mesh.n_vertices, mesh.n_vertices))
        depths = np.maximum(-z, 0.0)
        held = float(np.sum(depths))
        if held == 0:  # no depth: the lowest limit point touches the ground
            placement_hat[:, 2] -= lowering_hat * limit[int(np.argmin(z))].toarray().ravel()
            return 0.0
        placement_hat[:, 2] -= lowering_hat * (limit.T @ depths) / held
        return -lowering_hat / (2.0 * ground.stiffness * held)
