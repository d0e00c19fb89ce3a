"""The overdamped shell's drag as an energy term of one step's minimization (`Shell.terms`): the backward-Euler step
of ζ ṗ = f per unit rest area of the limit surface (docs/theory/transport.md, "Couplings"; kernels/drag.py).

    drag = Drag(shell, drag=ζ)
    shell.terms = (drag,)
    drag.set_interval(Δt)       # the step's length (device-side: captured relaxations stay valid)
    drag.begin_step(x)          # the step starts at x: every limit point's anchor where it is
    x = shell.relax(x, ...)     # minimizes E(x) + ½ (ζ/Δt) ∫ |p − a|² dω̄⁰: the end of the step

As Δt/ζ grows the step tends to the quasi-static equilibrium; for a finite ratio the shell relaxes towards it at
the rate its stiffness over ζ sets, so an instability grows per unit time rather than per step.

`LumpedDrag` is the walkers' form (wavewarp/implicit_dynamics.py): ζ per unit mass on the control points' lumped
masses M_I, ½ (ζ M_I/Δt) |x_I − a_I|², the mass matrix of the explicit overdamped solver.
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
from .kernels.drag import eval_drag, eval_lumped_drag
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


class LumpedDrag:
    """½ Σ_I k_I |x_I − a_I|² on the control points, k_I = ζ M_I / Δt (`set_stiffness`): the drag of the implicit
    overdamped walker step, the explicit solver's lumped masses M_I. The anchors a are set on the device
    (`anchors`, `begin_step`); where a = x the term adds nothing."""

    modules = (kernels_drag,)
    rigid_invariant = False  # it holds rigid motions

    def __init__(self, shell):
        self.shell = shell
        n = shell.mesh.n_vertices
        self.points_per_world = len(shell._energy_density) // shell.worlds
        if self.points_per_world < shell.mesh.vertices_per_world:
            raise ValueError("LumpedDrag adds each control point's energy to a quadrature point of its world: the "
                             "mesh has fewer quadrature points than vertices per world")
        with wp.ScopedDevice(shell.device):
            self.anchors = wp.array(shell.mesh.vertices.astype(shell._real), dtype=shell.vec3)
            self.stiffness = wp.zeros(n, dtype=shell.scalar)
            self._no_forces = wp.zeros(1, dtype=shell.vec3)

    def set_stiffness(self, stiffness) -> None:
        """k_I = ζ M_I / Δt per control point (host values, set outside captures)."""
        self.stiffness.assign(stiffness.astype(self.shell._real))

    def begin_step(self, x: wp.array) -> None:
        """Every anchor where x is: the term's force and energy vanish there."""
        wp.copy(self.anchors, x)

    def add_forces(self, x: wp.array, forces: wp.array | None, energy_density: wp.array | None) -> None:
        """forces += −∂E/∂x (when given); energy_density += E, per world (when given). Capturable."""
        with_forces, with_energy = forces is not None, energy_density is not None
        density = energy_density if with_energy else self.shell._energy_density
        eval_lumped_drag(x, self.anchors, self.stiffness, self.points_per_world, with_forces, with_energy,
                         forces if with_forces else self._no_forces, density)
