"""A shell resting on the ground, as energy terms of its relaxation (`Shell.terms`): the area ground's penalty,
gravity and, between load steps, Coulomb friction — the quasi-static limit of the overdamped walker
(docs/theory/dynamics.md, "The quasi-static limit"; kernels/resting_ground.py).

    ground = RestingGround(shell, stiffness=k_A, density=ρ, gravity=0.5, friction=0.1)
    shell.terms = (ground,)
    ground.begin_step(x)        # a load step starts: each point's anchor and pressure where it is
    x = shell.relax(x, ...)     # the step's equilibrium: sticking points stay, slipping ones are pulled by μ N
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from .checks import positive
from .geometry import evaluate, quadrature_points, spread_quadrature_forces
from .kernels import contact as kernels_contact
from .kernels import limit_surface as kernels_limit_surface
from .kernels import resting_ground as kernels_resting_ground
from .kernels import self_contact as kernels_self_contact
from .kernels.resting_ground import ground_pressure_kernel, resting_ground_kernel


class RestingGround:
    """The ground z = `height` under `shell` with pressure `stiffness` k z² per rest area at the limit surface's
    quadrature points, gravity `gravity` (g, downward; or a vector g for a tilted ground) on the mass per rest area
    `density`, and friction `friction` μ against each point's anchor (`begin_step`): μ N (√(|slip|² + ε²) − ε), N the
    point's pressure at its anchor, ε = `smoothing` (default 1e-6 of the mean control edge), so that a point sticks
    while its tangential pull is below μ N and is pulled by μ N once it slips. Before any `begin_step` the points
    have no load: frictionless. `QuasiStatic` begins every step."""

    modules = (kernels_resting_ground, kernels_limit_surface, kernels_contact, kernels_self_contact)

    def __init__(self, shell, *, stiffness: float, density: float, gravity=0.0, friction: float = 0.0,
                 height: float = 0.0, smoothing: float | None = None):  # fmt: skip
        if shell.gradient == "autodiff":
            raise ValueError("RestingGround needs the analytic gradient: build the Shell with gradient='analytic'")
        self.shell = shell
        self.stiffness = positive("stiffness", stiffness)
        self.density = positive("density", density)
        g = np.asarray(gravity, dtype=np.float64)
        self.gravity = np.array([0.0, 0.0, -float(g)]) if g.ndim == 0 else g.reshape(3)
        if not np.all(np.isfinite(self.gravity)):
            raise ValueError(f"gravity must be finite (g, or a 3-vector), got {gravity!r}")
        self.friction = float(friction)
        if not (self.friction >= 0 and math.isfinite(self.friction)):
            raise ValueError(f"friction must be a finite μ >= 0, got {friction!r}")
        self.height = float(height)
        edge = float(np.mean(shell.world_edge_lengths))
        self.smoothing = positive("smoothing", 1e-6 * edge if smoothing is None else smoothing)
        t = shell.tables
        self.area = evaluate(t, t.positions())["area"]
        n_q = t.n_quadrature_points
        with wp.ScopedDevice(shell.device):
            self.points, self.pressures = wp.zeros(n_q, dtype=shell.vec3), wp.zeros(n_q, dtype=shell.vec3)
            self.anchors, self.loads = wp.zeros(n_q, dtype=shell.vec3), wp.zeros(n_q, dtype=shell.scalar)

    def _points(self, x: wp.array) -> None:
        quadrature_points(self.shell.tables, x, self.points)

    def begin_step(self, x: wp.array) -> None:
        """A load step starts at positions x (`QuasiStatic` calls it before each relaxation): every point's anchor
        where it is, its load its pressure there."""
        s = self.shell.scalar
        self._points(x)
        wp.launch(ground_pressure_kernel, dim=len(self.points), inputs=[self.points, s(self.stiffness), s(self.height)],
                  outputs=[self.loads, self.anchors], device=self.shell.device)  # fmt: skip

    def add_forces(self, x: wp.array, forces: wp.array | None, energy_density: wp.array | None) -> None:
        """forces += −∂E/∂x (when given); energy_density[q] += q's share of E (when given). Capturable."""
        shell, t, s = self.shell, self.shell.tables, self.shell.scalar
        self._points(x)
        wp.launch(resting_ground_kernel, dim=t.n_quadrature_points,
                  inputs=[self.points, self.area, self.anchors, self.loads, s(self.stiffness), s(self.friction),
                          s(self.smoothing), s(self.density), shell.vec3(*self.gravity), s(self.height),
                          int(energy_density is not None)],
                  outputs=[self.pressures, shell._energy_density if energy_density is None else energy_density],
                  device=shell.device)  # fmt: skip
        if forces is not None:
            spread_quadrature_forces(t, self.pressures, self.area, forces, shell.deterministic)

    def normal_force(self, x: wp.array) -> np.ndarray:
        """Each world's total ground force Σ_q k z_q² w_q at positions x (host; one value per world)."""
        self._points(x)
        z = self.height - self.points.numpy()[:, 2]
        pressure = self.stiffness * np.where(z > 0, z, 0.0) ** 2
        return (pressure * self.area.numpy()).reshape(self.shell.worlds, -1).sum(axis=1)
