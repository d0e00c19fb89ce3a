"""The walker's settling taken back (docs/theory/gradients.md, "The settling"): a mixin of `WalkAdjoint`
(wavewarp/adjoint.py) that replays the settling from the placement — its inertial phase, then its overdamped one,
each from rest at c = 0 — checkpointed every ⌈√steps⌉ steps, takes each phase back by the walk's own step adjoint,
and adds the placement depth's share of the stiffness's gradient."""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from .dynamics import InertialSolver
from .geometry import limit_positions, limit_surface
from .kernels.adjoint import eval_count, eval_pull, eval_push


def placement_depths(mesh, per_area: bool) -> tuple:
    """(z, a, pen) of the placed `mesh`'s ground points as `ground_lift` weighs them: the limit points (a = 1), or with
    the area contact (`per_area`) the limit surface's quadrature points (a = dω̄⁰); pen = max(-z, 0)."""
    if per_area:
        surface = limit_surface(mesh, device="cpu", dtype="float64")
        z, weights = surface.points[:, 2], surface.area
    else:
        z = limit_positions(mesh, device="cpu", dtype="float64")[:, 2]
        weights = np.ones_like(z)
    return z, weights, np.maximum(-z, 0.0)


class SettlingAdjoint:
    """The settling's replay and adjoint; the host class provides the run, the shell, the walk's solver, the scratch
    arrays and stored rows, `_run`, `_ensure_rows`, `_contact_of` and `_step_adjoint`."""

    def _settle_phases(self) -> list:
        """[(solver, dt, steps)] of the run's settling as `settled_walker_dynamics` took it: inertial (damping η), then
        overdamped, each from rest (v = 0), at c = 0; the inertial solver and the replay's state made once (the captured
        graphs hold their arrays)."""
        run = self.run
        if self._settling is None:
            inertial = InertialSolver(self.shell, density=run.model.density, gravity=run.model.gravity,
                                      ground=self.solver.ground, damping=run.p.damping)  # fmt: skip
            self._settling = (inertial, inertial.state(run.mesh.vertices))
            if inertial.implicit:
                self._contact_of(inertial)
        return list(zip((self._settling[0], self.solver), run.settle_dt, run.settle_steps))

    def replay_settling(self) -> tuple:
        """The run's settling replayed from the placement (the adjoint's forward pass through it, on its own state);
        returns the settled positions and velocities (V × 3 NumPy each), the walk's start. Leaves the shell's reference
        at the wave's c."""
        self._settle_forward()
        self.shell.update_reference(self.wave.c)
        state = self._settling[1]
        return state.x.numpy().astype(np.float64), state.v.numpy().astype(np.float64)

    def _settle_forward(self) -> list:
        """The settling from the placement at c = 0, each phase from rest: [((solver, dt, steps), (checkpoints,
        spacing))] per phase (`_mechanics_forward`); the shell's reference is left at c = 0."""
        self.shell.update_reference(wp.zeros_like(self.wave.c))
        phases = self._settle_phases()
        state = self._settling[1]
        state.x.assign(self.run.mesh.vertices)  # the placement
        passes = []
        for solver, dt, steps in phases:
            state.v.zero_()
            passes.append(((solver, dt, steps), self._mechanics_forward(solver, dt, steps, state)))
        return passes

    def _settle_adjoint(self) -> None:
        """x̂, v̂ at the walk's start → the placement, through the settling's two phases (checkpointed as the walk),
        and the placement's depth into the stiffness's gradient."""
        passes = self._settle_forward()
        state = self._settling[1]
        for (solver, dt, steps), (checkpoints, every) in reversed(passes):
            for index in reversed(range(len(checkpoints[0]))):
                self._mechanics_backward(solver, dt, min(every, steps - index * every), state,
                                         [store[index] for store in checkpoints])  # fmt: skip
            self._scratch["v_hat"].zero_()  # each phase starts from rest
        if "stiffness" in self.wrt or self._mass_hat is not None:  # the rest shape: the contact area's share
            self._stiffness_placement = self._placement_stiffness()
        self.shell.update_reference(self.wave.c)

    def _mechanics_forward(self, solver, dt: float, steps: int, state) -> list:
        """`steps` mechanics steps of `solver` on `state` from where it is; returns the (x, v) checkpoints and their
        spacing, ⌈√steps⌉ steps."""
        every = max(1, math.ceil(math.sqrt(steps)))
        with wp.ScopedDevice(self.shell.device):
            checkpoints = [wp.empty((math.ceil(steps / every),) + a.shape, dtype=a.dtype) for a in (state.x, state.v)]
        self._ensure_rows(every + 1)
        for index, first in enumerate(range(0, steps, every)):
            wp.copy(checkpoints[0][index], state.x)
            wp.copy(checkpoints[1][index], state.v)
            self._run(lambda: solver.step(state, state, dt), min(every, steps - first), ("settle", id(solver)), 1)
        return checkpoints, every

    def _mechanics_backward(self, solver, dt: float, count: int, state, checkpoint: list) -> None:
        """`count` steps of `solver` again from `checkpoint`, stored, then backwards."""
        wp.copy(state.x, checkpoint[0])
        wp.copy(state.v, checkpoint[1])
        counter, s = self._counters["substep"], self._scratch
        counter.zero_()

        def recompute():
            eval_push(state.x, counter, self._xs)
            eval_push(state.v, counter, self._vs)
            eval_count(counter, 1)
            solver.step(state, state, dt)

        def backward():
            eval_count(counter, -1)
            eval_pull(self._xs, counter, 0, s["x"])
            eval_pull(self._vs, counter, 0, s["v"])
            eval_pull(self._vs, counter, 1, s["v_next"])
            self._step_adjoint(solver, s["x"], s["v"], s["v_next"], dt)

        self._run(recompute, count, ("settle recompute", id(solver)), 1)
        eval_push(state.x, counter, self._xs)
        eval_push(state.v, counter, self._vs)
        self._run(backward, count, ("settle backward", id(solver)), 1)

    def _placement_stiffness(self) -> float:
        """The stiffness gradient's share of the placement: the walker starts lowered by the depth d at which k Σ w pen²
        bears its weight (`ground_lift`), ∂z/∂k = Σ w pen² / (2k Σ w pen), pen the ground's points' depths below z = 0
        (limit points, w = 1; or quadrature points, w = dω̄⁰)."""
        _, weights, depths = placement_depths(self.run.mesh, self._area is not None)
        k = self.solver.ground.stiffness
        held = np.sum(weights * depths)
        lowering = np.sum(weights * depths**2) / (2.0 * k * held) if held > 0 else 0.0
        return lowering * float(np.sum(self._scratch["x_hat"].numpy()[:, 2]))
