"""A walker's chemistry step backwards (docs/theory/gradients.md, "The sensitive wave"): the explicit
FitzHugh–Nagumo step on the operator at x_n with the mass corrections W_p, then the conservative transport to the
surface at x_{n+1}:

    y = K(x_n) c,  r_0 = y / M,  r_{j+1} = r_j + (y - M_c r_j) / M  (j < p),  z = r_p
    c̃ = c + dt (f(c) - w - γ² z),  w̃ = w + dt ε (c - κ w)
    c' = c̃ M(x_n) / M(x_{n+1}),  w' = w̃ M(x_n) / M(x_{n+1})

(M the lumped mass, M_c the consistent one). Backwards, from ĉ', ŵ' and x̂: the transport gives c̃̂, w̃̂ and the two
masses' adjoints; the mechanics in between add to c̃̂ and ĉ through the ramped reference (`by_start`, `by_end`, per
quadrature point of the shell, filled by `Shell.rates_device`); the step gives ĉ, ŵ, and the Richardson steps taken
back give ŷ and M̂; ĉ += K ŷ; and every form's dependence on the positions (K's, M_c's, M's) adds to x̂ at x_n or
x_{n+1} (kernels/adjoint_wave.py). The insensitive wave (`moving=False`) steps on the rest surface and is not
transported: its forms' dependence on the rest shape adds to the caller's rest-shape accumulator instead."""

from __future__ import annotations

import warp as wp

from .kernels import check_one_device, one_device_methods
from .kernels.adjoint_wave import (
    eval_add_scaled,
    eval_divide_adjoint,
    eval_fhn_explicit_adjoint,
    eval_gather_point_factors,
    eval_operator_position_adjoint,
    eval_richardson_adjoint,
    eval_transport_adjoint,
)
from .kernels.laplace import divide_kernel, richardson_kernel
from .kernels.waves import eval_fhn_explicit


@one_device_methods("recompute", "transport_back", "step_back")
class WaveAdjoint:
    """The running adjoints ĉ, ŵ of a `FitzHughNagumo` stepper's explicit steps (module docstring); `shell_tables`: the
    shell's quadrature (its reference's points, where the mechanics hand back ĉ); `moving`: the operator follows the
    shell (the sensitive wave), else it stays on the rest surface."""

    def __init__(self, wave, shell_tables, moving: bool = True):
        check_one_device("WaveAdjoint", wave=wave.operator, shell_tables=shell_tables)
        self.solver, self.operator = wave.solver, wave.operator
        self.dt = wave.dt
        self.shell_tables = shell_tables
        self.corrections = self.solver.mass_corrections
        self.moving = bool(moving)
        self.conservative = self.solver.transport == "conservative" and self.moving
        n, scalar = self.operator.n_vertices, self.operator.scalar
        names = ("c_hat", "w_hat", "c_tilde", "w_tilde", "c_tilde_hat", "w_tilde_hat", "y", "y_hat", "r_hat", "q",
                 "product", "old_mass", "mass", "old_mass_hat", "mass_hat", "produced", "zeros")  # fmt: skip
        with wp.ScopedDevice(self.operator.device):
            self.v = {name: wp.zeros(n, dtype=scalar) for name in names}
            self.iterates = [wp.zeros(n, dtype=scalar) for _ in range(self.corrections + 1)]  # r_0 … r_p
            self.products = [wp.zeros(n, dtype=scalar) for _ in range(self.corrections)]  # M_c r_j
            points = shell_tables.n_quadrature_points
            vec3 = self.operator.vec3
            self.by_concentration = (wp.zeros(points, dtype=vec3), wp.zeros(points, dtype=vec3))  # (s₀, 0, 0)
        shell_tables.vertex_entries()  # built on first use: here, not inside a captured graph

    device = property(lambda self: self.operator.device)
    c_hat = property(lambda self: self.v["c_hat"])
    w_hat = property(lambda self: self.v["w_hat"])
    c_tilde = property(lambda self: self.v["c_tilde"])

    def zero(self) -> None:
        """ĉ = ŵ = 0: the objective does not read the chemistry at the walk's end."""
        self.v["c_hat"].zero_()
        self.v["w_hat"].zero_()

    def recompute(self, c, w, x) -> None:
        """The step from (c, w) on the surface at x again, as the solver took it: c̃, w̃, y, the iterates r_j and
        M_c r_j, and M(x) (the operator is left at x)."""
        op, v, dt = self.operator, self.v, self.dt
        if self.moving:
            op.update(x)
        wp.copy(v["old_mass"], op.mass_device)
        op.apply_device(c, v["y"])
        wp.launch(divide_kernel, dim=len(c), inputs=[v["y"], op.mass_device], outputs=[self.iterates[0]],
                  device=c.device)  # fmt: skip
        for j in range(self.corrections):
            wp.copy(self.iterates[j + 1], self.iterates[j])
            op.consistent_mass_device(self.iterates[j], self.products[j])
            wp.launch(richardson_kernel, dim=len(c), inputs=[v["y"], self.products[j], op.mass_device],
                      outputs=[self.iterates[j + 1]], device=c.device)  # fmt: skip
        wp.copy(v["c_tilde"], c)
        wp.copy(v["w_tilde"], w)
        s = self.solver
        eval_fhn_explicit(self.iterates[-1], op.mass_device, s.gamma, s.nu, s.kappa, s.epsilon, dt, v["c_tilde"],
                          v["w_tilde"], v["produced"])  # fmt: skip

    def transport_back(self, x_next, x_hat) -> None:
        """ĉ', ŵ' → c̃̂, w̃̂ through the transport to the surface at x_next, whose mass's share goes to x̂ (x̂ of
        x_next: before the mechanics are taken back). Zeroes the reference's per-point adjoints."""
        op, v = self.operator, self.v
        v["old_mass_hat"].zero_()
        v["mass_hat"].zero_()
        for points in self.by_concentration:
            points.zero_()
        if not self.conservative:
            wp.copy(v["c_tilde_hat"], v["c_hat"])
            wp.copy(v["w_tilde_hat"], v["w_hat"])
            return
        op.update(x_next)
        wp.copy(v["mass"], op.mass_device)
        for value, value_hat, tilde_hat in (("c_tilde", "c_hat", "c_tilde_hat"), ("w_tilde", "w_hat", "w_tilde_hat")):
            eval_transport_adjoint(v[value], v[value_hat], v["old_mass"], v["mass"], v[tilde_hat], v["old_mass_hat"],
                                   v["mass_hat"])  # fmt: skip
        eval_operator_position_adjoint(x_next, v["mass"], v["mass"], v["mass_hat"], 0.0, 0.0, op.tables, op.j_floor,
                                       x_hat)  # fmt: skip

    def step_back(self, c, x, x_hat) -> None:
        """The explicit step on the surface at x backwards (after the mechanics added their reference's share): ĉ, ŵ of
        the step's start, and x̂ += the forms' and the start mass's share (the rest surface's, fixed: its shape's)."""
        op, v, s = self.operator, self.v, self.solver
        if self.moving:
            op.update(x)
        start, end = self.by_concentration
        eval_gather_point_factors(end, self.shell_tables, v["product"], v["c_tilde_hat"])
        eval_fhn_explicit_adjoint(c, v["c_tilde_hat"], v["w_tilde_hat"], s.nu, s.kappa, s.epsilon, s.gamma, self.dt,
                                  v["c_hat"], v["w_hat"], v["r_hat"])  # fmt: skip
        v["y_hat"].zero_()
        for j in reversed(range(self.corrections)):
            eval_richardson_adjoint(v["r_hat"], v["y"], self.products[j], op.mass_device, v["y_hat"], v["old_mass_hat"],
                                    v["q"])  # fmt: skip
            op.consistent_mass_device(v["q"], v["product"])
            eval_add_scaled(v["r_hat"], v["product"], -1.0)
            eval_operator_position_adjoint(x, v["q"], self.iterates[j], v["zeros"], 0.0, -1.0, op.tables, op.j_floor,
                                           x_hat)  # fmt: skip
        eval_divide_adjoint(v["r_hat"], v["y"], op.mass_device, v["y_hat"], v["old_mass_hat"])
        op.apply_device(v["y_hat"], v["product"])
        eval_add_scaled(v["c_hat"], v["product"], 1.0)
        eval_operator_position_adjoint(x, v["y_hat"], c, v["old_mass_hat"], 1.0, 0.0, op.tables, op.j_floor, x_hat)
        eval_gather_point_factors(start, self.shell_tables, v["product"], v["c_hat"])
