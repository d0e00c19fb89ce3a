"""The implicit contact's adjoint (docs/theory/gradients.md, "Reverse mode"): the per-point solve and its Jacobi
sweeps (kernels/implicit_contact.py `eval_implicit_ground`), on the limit points (point contact) or the limit surface's
quadrature points (area contact), with the drag in the lab frame or the body frame, run again at a substep and then
taken backwards.

With G the points' gather from the control points (L, or the quadrature basis N) and S = Gᵀ weighted by each point's
area a (1 on limit points): forward, the responses r = scale × G M⁻¹ S 1_contact (piecewise constant in x, no
derivative), f⁰ = law(p, u*, r), and each sweep f^s = law(p, o^s, r) with o^s = u* + scale (G M⁻¹ S - r) f^(s-1).
Backward, given f̂ of the final forces: each sweep's law adjoint gives ô^s, ẑ and the parameters'; û* += ô^s and
f̂^(s-1) = scale (Sᵀ M⁻¹ Gᵀ - r) ô^s; the first law's adjoint gives û* its last share.

The body frame: before each pass's law the world's horizontal body velocity U takes a few Weiszfeld steps U' = U +
G(U)/h(U) (from 0 in the first pass, from the last pass's U in each sweep), the law sees the slip velocity o + U, and
every control point moves with the final U. Backward: Û starts as Σ_I ŵ_I (horizontal), each law's adjoint adds its
points' horizontal ô, and each step, taken back from its stored U, gives its points' share through Ĝ = Û'/h and
ĥ = -Û'·G/h² and adds their horizontal part to Û (kernels/adjoint_contact.py).

The masses (a rest shape's gradient; kernels/adjoint_shape.py): the final v = v* + scale M⁻¹ S f gives M̂_J -=
scale ŵ_J·(S f)_J / M_J², each sweep M̂_J -= scale (Gᵀô^s)_J·(S f^(s-1))_J / M_J² and r̂_i -= scale ô^s_i·f^(s-1)_i,
each law its r̂_i; the responses r_i = Σ_J G_iJ (S 1_contact)_J,x / M_J then give M̂_J -= (Gᵀ r̂)_J (S 1_contact)_J,x / M_J².
The area contact's weights a_q (S = Gᵀ diag(a)): â_q += f_q·scale (G M⁻¹ ŵ)_q from the final velocity, f^(s-1)_q·scale
(G M⁻¹ Gᵀ ô^s)_q from each sweep, 1_contact,q (G M⁻¹ Gᵀ r̂)_q,x from the responses, and in the body frame Ĝ·f_t,q +
ĥ |f_t,q|/|y_q| from each Weiszfeld step's sums G = Σ a f_t + external, h = Σ a |f_t|/|y|.
"""

from __future__ import annotations

from dataclasses import replace

import warp as wp

from .geometry import limit_coupling
from .kernels import check_one_device, one_device_methods
from .kernels.adjoint import eval_add, eval_coupling_transpose, eval_weighted_dot
from .kernels.adjoint_contact import (
    eval_body_step_adjoint,
    eval_horizontal_sum,
    eval_implicit_law_adjoint,
    implicit_laws,
)
from .kernels.adjoint_shape import (
    eval_first_component,
    eval_inverse_mass_share,
    eval_point_weight_share,
    eval_response_share,
)
from .kernels.contact import ground_motion, spread_to_control_points
from .kernels.implicit_contact import (
    Coupling,
    add_body_velocity_kernel,
    body_friction_sums_kernel,
    contact_indicator_kernel,
    eval_limit_sweeps,
    implicit_contact_kernel,
    limit_coupled_velocity_kernel,
    limit_response_kernel,
    quadrature_coupled_velocity_kernel,
    quadrature_response_kernel,
    solve_body_velocity,
)
from .kernels.reduce import REDUCTION_BLOCK


@one_device_methods("forward", "backward")
class ImplicitContactAdjoint:
    """The implicit contact of `solver` (an InertialSolver or OverdampedSolver with Ground(solve="implicit"), the drag
    in the lab or the body frame, one world, float64): `forward(x, v_star, scale, dt)` solves it again storing every
    sweep (and every body velocity), `backward(force_hat, ...)` takes it back."""

    def __init__(self, solver):
        check_one_device("ImplicitContactAdjoint", solver=solver, mask=solver.mask, mass=solver.inverse_mass)
        self.solver, self.ground, self.mask = solver, solver.ground, solver.mask
        self.device = solver.device
        self.point = self.ground.contact == "point"
        self.patch, area = solver.ground_tables()
        self.tables = ([self.mask.ring_start, self.mask.ring, self.mask.centre_weight, self.mask.ring_weight]
                       if self.point else list(self.patch))  # fmt: skip
        n, vertices, sweeps = solver.ground_points, len(solver.mass), self.ground.sweeps
        self.gradient = wp.zeros(5, dtype=wp.float64, device=solver.device)  # ∂/∂(k, β, μ, k_f, scale)
        with wp.ScopedDevice(solver.device):
            self.area = wp.ones(n, dtype=wp.float64) if area is None else area  # a: dω̄⁰, or 1 on limit points
            self.ones = wp.ones(n, dtype=wp.float64)
            self.p, self.u_star = wp.zeros(n, dtype=wp.vec3d), wp.zeros(n, dtype=wp.vec3d)
            self.response, self.normal = wp.zeros(n, dtype=wp.float64), wp.zeros(n, dtype=wp.float64)
            self.no_response, self.zeros = wp.zeros(n, dtype=wp.float64), wp.zeros(n, dtype=wp.vec3d)
            self.load = wp.zeros(vertices, dtype=wp.vec3d)
            self.body = wp.zeros(1, dtype=wp.vec3d)
            self.forces = [wp.zeros(n, dtype=wp.vec3d) for _ in range(sweeps + 1)]  # f^0 … f^S
            self.others = [wp.zeros(n, dtype=wp.vec3d) for _ in range(sweeps + 1)]  # o^1 … o^S (o^0 = u*)
            self.o_hat, self.f_hat, self.gathered = (wp.zeros(n, dtype=wp.vec3d) for _ in range(3))
            self.response_hat, self.indicator = wp.zeros(n, dtype=wp.float64), wp.zeros(n, dtype=wp.vec3d)
            self.no_weights = wp.zeros(0, dtype=wp.float64)
            self.spread = wp.zeros(vertices, dtype=wp.vec3d)  # S f of a pass (the masses' share)
        self.coupling = (Coupling.of(limit_coupling(solver.shell.mesh, 1.0 / solver.mass), wp.float64, solver.device)
                         if self.point else None)  # fmt: skip
        self.frame = solver.body  # kernels/implicit_contact.py BodyFrame
        if self.frame.solve:
            first, later = self.frame.iterations
            with wp.ScopedDevice(solver.device):  # each pass's body velocities U_0 … U_K, its sums and seeds
                counts = [first] + [later] * sweeps
                self.iterates = [[wp.zeros(1, dtype=wp.vec3d) for _ in range(count + 1)] for count in counts]
                self.sums = [wp.zeros(1, dtype=wp.vec3d), wp.zeros(1, dtype=wp.float64)]
                self.seeds = [wp.zeros(1, dtype=wp.vec3d), wp.zeros(1, dtype=wp.float64)]
                self.body_hat, self.slip = wp.zeros(1, dtype=wp.vec3d), wp.zeros(n, dtype=wp.vec3d)
            # each Weiszfeld step's frame: the solver's, stepping its own iterate
            self.steps = [[replace(self.frame, velocity=iterate) for iterate in iterates[1:]]
                          for iterates in self.iterates]  # fmt: skip

    def _coupled(self, forces, predictor, response, area, scale: float, out) -> None:
        """out = predictor + scale (G M⁻¹ S_area forces - response forces) (the sweep's velocity without the point's
        own force; `area` weights the spread: the points' areas, or 1 for the transpose's first half)."""
        self.load.zero_()
        spread_to_control_points(self.ground, forces, self.mask, self.patch, None if self.point else area, self.load)
        kernel = limit_coupled_velocity_kernel if self.point else quadrature_coupled_velocity_kernel
        wp.launch(kernel, dim=len(out), inputs=[self.load, self.solver.inverse_mass, wp.float64(scale), *self.tables,
                                                predictor, response, forces],
                  outputs=[out], device=out.device)  # fmt: skip

    def forward(self, x, v_star, scale: float, dt: float) -> None:
        """The contact solve at positions x from the predictor v_star, every sweep's forces and velocities kept."""
        device, n = x.device, len(self.p)
        ground_motion(self.ground, x, v_star, self.mask, self.patch, self.p, self.u_star)
        if self.point and not self.frame.solve:  # the solver's one launch a pass, each pass into its own buffers
            eval_limit_sweeps(self.p, self.u_star, self.coupling, implicit_laws(self.ground, scale, dt), self.body,
                              self.response, self.normal, self.forces, self.others)  # fmt: skip
            return
        wp.launch(contact_indicator_kernel, dim=n, inputs=[self.p], outputs=[self.forces[0]], device=device)
        self.load.zero_()
        spread_to_control_points(self.ground, self.forces[0], self.mask, self.patch, None if self.point else self.area,
                                 self.load)  # fmt: skip
        kernel = limit_response_kernel if self.point else quadrature_response_kernel
        wp.launch(kernel, dim=n, inputs=[self.load, self.solver.inverse_mass, *self.tables], outputs=[self.response],
                  device=device)  # fmt: skip
        laws = implicit_laws(self.ground, scale, dt)
        velocities = self.u_star
        for s in range(len(self.forces)):
            if s > 0:
                self._coupled(self.forces[s - 1], self.u_star, self.response, self.area, scale, self.others[s])
                velocities = self.others[s]
            body = self._solve_body(s, velocities, laws) if self.frame.solve else self.body
            wp.launch(implicit_contact_kernel, dim=n, inputs=[self.p, velocities, self.response, *laws, body],
                      outputs=[self.normal, self.forces[s]], device=device)  # fmt: skip

    def _sums(self, velocities, body, laws) -> None:
        """self.sums = the net friction Σ a f_t and the stiffness Σ a |f_t|/|y| at body velocity `body` (the sums of a
        Weiszfeld step, without the step)."""
        for total in self.sums:
            total.zero_()
        frame = self.frame
        wp.launch(body_friction_sums_kernel, dim=frame.threads,
                  inputs=[self.p, velocities, self.response, frame.weight, *laws, body, frame.threads],
                  outputs=self.sums, block_dim=REDUCTION_BLOCK, device=self.p.device)  # fmt: skip

    def _solve_body(self, s: int, velocities, laws):
        """Pass s's Weiszfeld steps of U (kernels/implicit_contact.py `solve_body_velocity`), every iterate kept; the last."""
        iterates = self.iterates[s]
        if s == 0:
            iterates[0].zero_()
        else:
            wp.copy(iterates[0], self.iterates[s - 1][-1])
        for step, frame in enumerate(self.steps[s]):  # U_{k+1} = U_k + G/h, into its own iterate
            wp.copy(iterates[step + 1], iterates[step])
            solve_body_velocity(frame, self.p, velocities, self.response, laws, 1)
        return iterates[-1]

    def _spread_forces(self, forces) -> None:
        """self.spread = S forces (the points' forces on the control points)."""
        self.spread.zero_()
        spread_to_control_points(self.ground, forces, self.mask, self.patch, None if self.point else self.area,
                                 self.spread)  # fmt: skip

    def backward(self, force_hat, scale: float, dt: float, u_star_hat, p_hat, velocity_hat, mass_hat=None,
                 weight_hat=None) -> None:  # fmt: skip
        """Given f̂ of the final forces at the points and ŵ (`velocity_hat`) of the control points' final velocities:
        u_star_hat = û* (overwritten), p_hat += ẑ, and `gradient` += ∂/∂(k, β, μ, k_f, scale) of f̂ · f, the final
        velocity's share of scale included (and, in the body frame, U's: every control point moves with it);
        `mass_hat` (where given) += the masses' share, `weight_hat` the area contact's weights' (module docstring;
        `force_hat` is then scale (G M⁻¹ ŵ)_q a_q)."""
        gradient, laws, inverse_mass = self.gradient, implicit_laws(self.ground, scale, dt), self.solver.inverse_mass
        eval_weighted_dot(force_hat, self.forces[-1], 1.0 / scale, 4, gradient)  # v = v* + scale M⁻¹ S f
        self.response_hat.zero_()
        if mass_hat is not None:
            self._spread_forces(self.forces[-1])
            eval_inverse_mass_share(velocity_hat, self.spread, inverse_mass, scale, mass_hat)
        if weight_hat is not None:
            eval_point_weight_share(self.forces[-1], force_hat, self.area, weight_hat)
        wp.copy(self.f_hat, force_hat)
        u_star_hat.zero_()
        if self.frame.solve:
            self.body_hat.zero_()
            eval_horizontal_sum(velocity_hat, self.body_hat)
        for s in reversed(range(len(self.forces))):
            velocity = slip = self.u_star if s == 0 else self.others[s]
            if self.frame.solve:  # the law saw o + U
                wp.copy(self.slip, velocity)
                wp.launch(add_body_velocity_kernel, dim=len(slip), inputs=[self.iterates[s][-1]], outputs=[self.slip],
                          device=slip.device)  # fmt: skip
                slip = self.slip
            eval_implicit_law_adjoint(self.ground, self.p, slip, self.response, scale, dt, self.f_hat, self.o_hat,
                                      p_hat, gradient, self.response_hat)  # fmt: skip
            if self.frame.solve:
                weights = self.no_weights if weight_hat is None else weight_hat
                self._body_backward(s, velocity, scale, dt, laws, p_hat, weights)
            eval_add(u_star_hat, self.o_hat)
            if s > 0:  # o^s = u* + scale (G M⁻¹ S - r) f^(s-1): f̂^(s-1), then ∂/∂scale
                self._coupled(self.o_hat, self.zeros, self.no_response, self.ones, scale, self.gathered)
                if mass_hat is not None:  # self.load = Gᵀ ô^s
                    eval_response_share(self.o_hat, self.forces[s - 1], scale, self.response_hat)
                    self._spread_forces(self.forces[s - 1])
                    eval_inverse_mass_share(self.load, self.spread, inverse_mass, scale, mass_hat)
                if weight_hat is not None:  # self.gathered = scale G M⁻¹ Gᵀ ô^s
                    eval_point_weight_share(self.forces[s - 1], self.gathered, self.ones, weight_hat)
                eval_coupling_transpose(self.gathered, self.area, self.response, scale, self.o_hat, self.f_hat)
                eval_weighted_dot(self.f_hat, self.forces[s - 1], 1.0 / scale, 4, gradient)
        if mass_hat is not None:  # the responses r = G M⁻¹ S 1_contact
            wp.launch(contact_indicator_kernel, dim=len(self.p), inputs=[self.p], outputs=[self.indicator],
                      device=self.p.device)  # fmt: skip
            self._spread_forces(self.indicator)
            eval_first_component(self.response_hat, self.gathered)
            self.load.zero_()
            spread_to_control_points(self.ground, self.gathered, self.mask, self.patch, None if self.point else self.ones,
                                     self.load)  # fmt: skip
            eval_inverse_mass_share(self.load, self.spread, inverse_mass, 1.0, mass_hat)
            if weight_hat is not None:  # 1_contact (G M⁻¹ Gᵀ r̂)_x
                self._coupled(self.gathered, self.zeros, self.no_response, self.ones, 1.0, self.o_hat)
                eval_point_weight_share(self.indicator, self.o_hat, self.ones, weight_hat)

    def _body_backward(self, s: int, velocities, scale: float, dt: float, laws, p_hat, weight_hat) -> None:
        """Pass s's body velocity backwards: Û += the law's horizontal ô, then its Weiszfeld steps, last first, each
        adding its points' share to ô and Û (Û is then the adjoint of the pass's starting U, the last pass's), and
        to the points' weights' adjoint where `weight_hat` has them."""
        eval_horizontal_sum(self.o_hat, self.body_hat)
        iterates = self.iterates[s]
        for step in reversed(range(len(iterates) - 1)):
            self._sums(velocities, iterates[step], laws)
            eval_body_step_adjoint(self.ground, self.p, velocities, iterates[step], self.response, self.frame.weight,
                                   scale, dt, self.sums, self.frame.external, self.seeds, self.o_hat, p_hat,
                                   self.gradient, self.body_hat, self.response_hat, weight_hat)  # fmt: skip
