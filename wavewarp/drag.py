"""The overdamped shell's drag as an energy term of one step's minimization (`Shell.terms`): the backward-Euler step
of ζ ṗ = f per unit rest area of the limit surface (docs/theory/transport.md, "Couplings"; kernels/drag.py).

    drag = Drag(shell, drag=ζ)
    shell.terms = (drag,)
    drag.set_interval(Δt)       # the step's length (device-side: captured relaxations stay valid)
    drag.begin_step(x)          # the step starts at x: every limit point's anchor where it is
    x = shell.relax(x, ...)     # minimizes E(x) + ½ (ζ/Δt) ∫ |p − a|² dω̄⁰: the end of the step

As Δt/ζ grows the step tends to the quasi-static equilibrium; for a finite ratio the shell relaxes towards it at
the rate its stiffness over ζ sets, so an instability grows per unit time rather than per step.
"""

from __future__ import annotations

import math

import warp as wp

from .checks import positive
from .geometry import evaluate, quadrature_points, spread_quadrature_forces
from .kernels import contact as kernels_contact
from .kernels import drag as kernels_drag
from .kernels import limit_surface as kernels_limit_surface
from .kernels import self_contact as kernels_self_contact
from .kernels.drag import eval_drag
from .shell import per_world


class Drag:
    """Viscous drag `drag` ζ (force per rest area per unit velocity) on the limit surface of `shell`, over steps of
    length `set_interval(Δt)` that start where `begin_step(x)` finds the surface. Before any `begin_step` every
    anchor is at the rest shape."""

    # the modules of its launches (the drag; the quadrature points; their spread and gathered forces)
    modules = (kernels_drag, kernels_limit_surface, kernels_contact, kernels_self_contact)
    rigid_invariant = False  # it holds rigid motions: the Newton finish must not project them out (wavewarp/newton.py)

    def __init__(self, shell, *, drag):  # one ζ, or one per batched world
        if shell.gradient == "autodiff":
            raise ValueError("Drag needs the analytic gradient: build the Shell with gradient='analytic'")
        self.drag = per_world("drag ζ (force per rest area per unit velocity)", drag, shell.worlds, check=positive)
        self.shell, self.interval = shell, None
        t = shell.tables
        self.area = evaluate(t, t.positions())["area"]
        n_q = t.n_quadrature_points
        with wp.ScopedDevice(shell.device):
            self.points, self.pressures = wp.zeros(n_q, dtype=shell.vec3), wp.zeros(n_q, dtype=shell.vec3)
            self.anchors = wp.zeros(n_q, dtype=shell.vec3)
            self.coefficient = wp.zeros(shell.worlds, dtype=shell.scalar)
        quadrature_points(t, t.positions(), self.anchors)

    def set_interval(self, interval: float) -> None:
        """The step's length Δt (> 0): the coefficients ζ/Δt, on the device."""
        interval = float(interval)
        if not (interval > 0 and math.isfinite(interval)):
            raise ValueError(f"the step's interval must be a finite Δt > 0, got {interval!r}")
        if interval != self.interval:
            self.interval = interval
            self.coefficient.assign((self.drag / interval).astype(self.shell._real))

    def begin_step(self, x: wp.array) -> None:
        """A step starts at positions x: every limit point's anchor where it is now."""
        quadrature_points(self.shell.tables, x, self.anchors)

    def add_forces(self, x: wp.array, forces: wp.array | None, energy_density: wp.array | None) -> None:
        """forces += −∂E/∂x (when given); energy_density[q] += q's share of E (when given). Capturable."""
        shell = self.shell
        quadrature_points(shell.tables, x, self.points)
        density = shell._energy_density if energy_density is None else energy_density
        with_energy = energy_density is not None
        eval_drag(self.points, self.anchors, self.area, self.coefficient, with_energy, self.pressures, density)
        if forces is not None:
            spread_quadrature_forces(shell.tables, self.pressures, self.area, forces, shell.deterministic)

    def twin(self, shell) -> Drag:
        """The same drag on `shell` (the float64 twin of a float32 shell's Newton finish); `share` gives it the step."""
        twin = Drag(shell, drag=self.drag)
        self.share(twin)
        return twin

    def share(self, twin: Drag) -> None:
        """Give `twin` this step's coefficients and anchors (in its dtype)."""
        twin.interval = self.interval
        twin.coefficient.assign(self.coefficient.numpy().astype(twin.shell._real))
        twin.anchors.assign(self.anchors.numpy().astype(twin.shell._real))
