"""The rest shape's gradient in reverse mode (docs/theory/gradients.md, "The rest shape"): a mixin of `WalkAdjoint`
(wavewarp/adjoint.py) that gathers, over a whole run, every way the control points X of the walker's mesh reach J.

The placed mesh is X stretched along x by the elongation and lowered onto the ground: x⁰ = s ∘ X + (lift - depth) ẑ.
From it come the settling's start (x̂⁰ of the settling's adjoint), the rest forms and the rest volume (their adjoints
taken to the control points), the pulse's width (σ = 1.5 × the mean edge / R, where automatic), the insensitive
wave's rest surface and pulse, and the masses M_J = ρ ∫ N_J dω̄⁰. The masses' adjoint M̂ gathers the steps' F/M,
the inertial damping's rigid-body motion, the implicit contact's M⁻¹ (kernels/adjoint_shape.py), the objective's
mass-weighted centre, the automatic drag ζ = 2β max_J (Lᵀ1)_J / M_J and the placement's weight; it reaches the
control points as the lumped mass's derivative (kernels/adjoint_wave.py `operator_position_adjoint_kernel` with m =
ρM̂). The placement: lift - depth moves by -Σ a_i pen_i dz_i / S - dW / (2kS) + Σ pen_i² da_i / (2S), S = Σ a pen
(the lowest point's own move cancels), z_i the ground points' heights, pen_i their depths below the ground, a_i their
weights (1 on limit points), W = ρ g × the limit surface's area. The area contact's weights a_q = dω̄⁰_q (the spread
of its pressures, kernels/adjoint_shape.py) reach X as a rest-metric adjoint, and its contact area per point a/V
through k, β (and an automatic ζ) given per it; in the body frame they weigh the friction balance too
(wavewarp/adjoint_contact.py).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sparse
import warp as wp

from .device import mat22
from .adjoint_settling import placement_depths
from .geometry import SurfaceTables, evaluate, limit_positions
from .kernels.contact import spread_to_control_points
from .kernels.adjoint_rest import eval_rest_forms_adjoint
from .kernels.adjoint_shape import eval_inverse_mass_share, eval_rigid_motion_mass_share
from .kernels.adjoint_wave import eval_operator_position_adjoint
from .laplace import LaplaceBeltrami
from .walker_gradients import WalkerGradientError

AREA_RULE = "3"  # the quadrature of the placement's weight (walker.py `place_walker`: the limit surface's area)


def check_rest_shape(p) -> None:
    """Raise WalkerGradientError, naming the fix, where the reverse mode does not give a walker's rest-shape gradient."""
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
        them). The implicit contact's own share is taken in its backward pass; an explicit step's ground forces are left
        evaluated at x, v for the ground's adjoint (its weights' share)."""
        s, overdamped = self._scratch, solver is self.solver
        w_hat = s["v_star_hat"] if solver.implicit else s["w_hat"]
        scale = 1.0 / solver.drag if overdamped else dt
        forces = solver.force_buffer if solver.implicit else solver.step_forces(x, v)  # the predictor left F
        eval_inverse_mass_share(w_hat, forces, solver.inverse_mass, scale, self._mass_hat)
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
        area_hat = 0.0  # the limit surface's area's adjoint (AREA_RULE)
        if self._weight_hat is None and p.drag == 0:  # ζ = 2β max_J (Lᵀ1)_J / M_J
            column_sums = self.solver.limit_column_sums()
            top = int(np.argmax(column_sums / mass))
            mass_hat[top] -= self.solver.drag / mass[top] * self._gradients()["drag"]
        if self._weight_hat is not None and p.contact_area == 0:  # k, β per area a / V; ζ = 2β/(per ρ) where automatic
            gradients, per = self._gradients(), run.resolved["contact_area"]
            per_hat = -(gradients["stiffness"] * p.stiffness + gradients["contact_damping"] * p.contact_damping) / per
            if p.drag == 0:
                per_hat -= self.solver.drag / per * gradients["drag"]
            area_hat += per_hat / run.mesh.n_vertices
        x_hat = placement_hat.copy()
        rest = run.mesh.vertices
        density = run.model.density
        with wp.ScopedDevice(shell.device):
            rest_x, out = wp.array(rest, dtype=wp.vec3d), wp.zeros(len(rest), dtype=wp.vec3d)
            weight_hat = self._placement_share(rest_x, out)
            area_hat += weight_hat * density * run.model.gravity
            lumped = LaplaceBeltrami(run.mesh, rule=shell.rule, device=shell.device, dtype="float64")
            zeros = wp.zeros(len(rest), dtype=wp.float64)
            eval_operator_position_adjoint(rest_x, zeros, zeros, wp.array(density * mass_hat, dtype=wp.float64), 0.0,
                                           0.0, lumped.tables, lumped.j_floor, out)  # fmt: skip
            area = lumped if shell.rule == AREA_RULE else LaplaceBeltrami(run.mesh, rule=AREA_RULE, device=shell.device,
                                                                          dtype="float64")  # fmt: skip
            eval_operator_position_adjoint(rest_x, zeros, zeros, wp.full(len(rest), area_hat, dtype=wp.float64), 0.0,
                                           0.0, area.tables, area.j_floor, out)  # fmt: skip
            eval_rest_forms_adjoint(rest_x, *self._rest_forms_hat, shell.tables, out)
            if self._weight_hat is not None:  # the area contact's weights dω̄⁰ at the shell's points
                weights_to_control_points(self._weight_hat.numpy(), shell.tables, rest_x, out)
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

    def _placement_share(self, rest_x, out) -> float:
        """The placed mesh's lowering (lift - depth): its adjoint, Σ x̂⁰_z (`self._scratch`'s x̂ after the settling),
        taken to the ground points' heights (the limit points, or the AREA_RULE quadrature points of the area
        contact, whose weights a_q it moves too) and added to `out`; returns Ŵ, the placement weight's adjoint
        (module docstring; with the area contact Σ a pen stands for Σ pen, and Σ pen² da / (2 Σ a pen) is added)."""
        mesh, ground = self.run.mesh, self.solver.ground
        lowering_hat = float(np.sum(self._scratch["x_hat"].numpy()[:, 2]))
        z, weights, depths = placement_depths(mesh, ground.contact == "area")
        held = float(np.sum(weights * depths))
        rows, cols, vals = mesh.limit_mask_matrix()
        limit = sparse.csr_matrix((vals, (rows, cols)), shape=(mesh.n_vertices, mesh.n_vertices))
        heights_hat = np.zeros((mesh.n_vertices, 3))
        if held == 0:  # no depth: the lowest limit point touches the ground
            lowest = int(np.argmin(limit_positions(mesh, device="cpu", dtype="float64")[:, 2]))
            heights_hat[:, 2] = -lowering_hat * limit[lowest].toarray().ravel()
            out.assign(out.numpy() + heights_hat)
            return 0.0
        if ground.contact == "point":
            heights_hat[:, 2] = -lowering_hat * (limit.T @ depths) / held
            out.assign(out.numpy() + heights_hat)
        else:
            tables = SurfaceTables.of(mesh, AREA_RULE, device=rest_x.device, dtype="float64")
            points = np.zeros((len(z), 3))
            points[:, 2] = -lowering_hat * depths / held
            spread_to_control_points(ground, wp.array(points, dtype=wp.vec3d), self.solver.mask, tables.patch(),
                                     wp.array(weights, dtype=wp.float64), out)  # fmt: skip
            weights_to_control_points(lowering_hat * depths**2 / (2.0 * held), tables, rest_x, out)
        return -lowering_hat / (2.0 * ground.stiffness * held)


def weights_to_control_points(weight_hat: np.ndarray, tables, x, out) -> None:
    """out += ∂(Σ_q ŵ_q dω̄⁰_q)/∂x: dω̄⁰ = √det ā⁰ w, so Â⁰_q = ŵ_q ½ dω̄⁰_q (ā⁰_q)⁻¹, taken to the control points as
    the rest forms' adjoint (`eval_rest_forms_adjoint`)."""
    forms = evaluate(tables, x)
    metric, area = forms["metric"].numpy().astype(np.float64), forms["area"].numpy().astype(np.float64)
    metric_hat = (0.5 * weight_hat * area)[:, None, None] * np.linalg.inv(metric)
    m22 = mat22(wp.float64)
    eval_rest_forms_adjoint(x, wp.array(metric_hat, dtype=m22, device=x.device),
                            wp.zeros(len(metric_hat), dtype=m22, device=x.device), tables, out)  # fmt: skip
