"""Quasi-static relaxation of a Shell: preconditioned nonlinear CG (Polak–Ribière+) with an
Armijo line search on a parabolic step estimate (docs/theory/shell.md; choice and measurements in
docs/theory/shell.md). Vectors and the line search's scalars live on the device: a relaxation is one
captured `wp.capture_while` loop, launched once, its result read once.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .device import run_steps
from .kernels import contact as kernels_contact
from .kernels import limit_surface as kernels_limit_surface
from .kernels import reduce as kernels_reduce
from .kernels import relax as kernels_relax
from .kernels import self_contact as kernels_self_contact
from .kernels import shell as kernels_shell
from .kernels.relax import (
    ACCEPTED,
    BUDGET_SPENT,
    CONVERGED,
    ENERGY,
    FAR_TRIAL,
    FLAGS_SIZE,
    ITERATION,
    OUTSIDE_SKIN,
    RESIDUAL,
    SEARCH_SIZE,
    STALE,
    STATUS,
    TOL,
    accept_kernel,
    beta_kernel,
    continue_kernel,
    direction_kernel,
    iteration_kernel,
    line_search_kernel,
    outcome_kernel,
    restart_kernel,
    resume_kernel,
    slope_kernel,
    start_kernel,
    start_search_kernel,
    trial_kernel,
)
from .newton import ENERGY_NOISE, NewtonFinish

METHODS = ("ncg", "newton", "auto")
# a CG stop at the round-off floor within this factor of tol is the dtype's floor: Newton cannot help
ROUND_OFF_SLACK = 10.0
# Newton steps a finish may take: every step lowers the energy, and a snap-through to a distant
# equilibrium took 132–137 (docs/theory/shell.md#newton-finish)
NEWTON_STEPS = 500


class RelaxationError(RuntimeError):
    """`Shell.relax` did not reach its tolerance; `.residual` is where it stopped, `.x` the positions
    there, `.round_off` whether it stopped because no lower energy could be resolved, `.iterations`
    how many it took. Batched worlds: `.worlds` lists those that did not converge (the others did)
    and `.failures` maps each to its (residual, round_off); the scalars are the worst world's."""

    def __init__(self, message: str, residual: float, x: np.ndarray, round_off: bool = False, iterations: int = 0,
                 worlds=None, failures=None):  # fmt: skip
        super().__init__(message)
        self.residual = residual
        self.x = x
        self.round_off = round_off
        self.iterations = iterations
        self.worlds = worlds
        self.failures = failures if failures is not None else {0: (residual, round_off)}


def _inverse_stiffness(shell) -> np.ndarray:
    """1/k with k = (Y h / ℓ̄² + Y h³ / ℓ̄⁴) Ā, Ā the mean control area per vertex (each world's own).

    One value for all vertices of a world: it sets the step scale without giving the search
    direction a net translation or rotation (internal forces have none), so rigid modes cannot stall it.
    """
    mesh = shell.mesh
    a, b, c = (mesh.vertices[mesh.triangles[:, k]] for k in range(3))
    areas = np.linalg.norm(np.cross(b - a, c - a), axis=1).reshape(shell.worlds, -1)
    inverse = []
    for area, young, h, ell in zip(areas, shell._young, shell._thickness, shell.world_edge_lengths):
        area_per_vertex = 0.5 * area.sum() / mesh.vertices_per_world
        inverse.append(1.0 / (float(young) * float(h) * (1 / ell**2 + float(h) ** 2 / ell**4) * area_per_vertex))
    return np.repeat(inverse, mesh.vertices_per_world)


class Relaxation:
    """Preconditioned nonlinear CG (Polak–Ribière+) for one shell, resident on its device (batched
    worlds: one line search and one convergence test per world, in the same launches).

    Vectors and the scalar state of the line search live on the device; one loop pass evaluates
    one trial point and, when the search accepts it, updates the CG direction (kernels/relax.py).
    The whole relaxation runs as one `wp.capture_while` loop, captured once per shell as a graph
    (CUDA, and Warp's CPU graphs), so a relaxation costs one launch and one read of its result.
    """

    def __init__(self, shell):
        self.shell = shell
        n, worlds, vec3, scalar = shell.mesh.n_vertices, shell.worlds, shell.vec3, shell.scalar
        with wp.ScopedDevice(shell.device):
            self.x, self.trial = wp.zeros(n, dtype=vec3), wp.zeros(n, dtype=vec3)
            self.forces, self.trial_forces = wp.zeros(n, dtype=vec3), wp.zeros(n, dtype=vec3)
            self.s, self.s_old, self.direction = (wp.zeros(n, dtype=vec3) for _ in range(3))
            self.inverse_stiffness = wp.array(_inverse_stiffness(shell).astype(shell._real), dtype=scalar)
            self.energy, self.trial_energy = wp.zeros(worlds, dtype=wp.float64), wp.zeros(worlds, dtype=wp.float64)
            self.sums = wp.zeros(3 * worlds, dtype=scalar)
            self.largest, self.dot = wp.zeros(worlds, dtype=scalar), wp.zeros(worlds, dtype=scalar)
            self.search = wp.zeros(SEARCH_SIZE * worlds, dtype=wp.float64)
            self.flags, self.condition = wp.zeros(FLAGS_SIZE * worlds, dtype=wp.int32), wp.zeros(1, dtype=wp.int32)
        self.history = None  # E after each accepted step, capacity max_iterations + 1
        self.forget_graphs()
        shell.listen(self.forget_graphs)  # a new V̄ or term: the captured loop is captured anew
        # autodiff forces allocate per evaluation (Tape): they run the same loop from the host
        self.capture = shell.gradient != "autodiff"

    def run(self, x: wp.array, tol: float, max_iterations: int, callback=None, out: wp.array | None = None,
            resume: bool = False):  # fmt: skip
        """Relax from x to max |F| <= tol · Y h ℓ̄; returns the positions (V, 3) in float64, or, with
        `out` (a device array, may be x), writes them there and returns None; after a STALE stop it
        returns None and writes nothing. `resume` goes on from a STALE stop with the CG state,
        iteration count and budget as they were."""
        shell = self.shell
        if not resume:
            self.prepare(tol, max_iterations)
            wp.copy(self.x, x)
        solve, graphs = (self._resume, self._resume_graphs) if resume else (self._solve, self._graphs)
        if callback is not None:
            with wp.ScopedDevice(shell.device):
                if resume:
                    wp.launch(resume_kernel, dim=1, outputs=[self.flags, self.condition])
                else:
                    self._start()
                self._loop(callback, announce=not resume)
        else:
            modules = (kernels_relax, kernels_shell, kernels_reduce)
            if shell.self_contact is not None:
                modules += (kernels_self_contact, kernels_limit_surface, kernels_contact)
            for term in shell.terms:
                modules += term.modules
            run_steps(solve, 1, device=shell.device, graphs=graphs, modules=modules, capture=self.capture)
        return self._result(tol, out)

    def prepare(self, tol: float, max_iterations: int) -> None:
        """Set every world's tolerance and budget (`run` does; `solve` needs it first), on the host, outside captures."""
        shell, worlds = self.shell, self.shell.worlds
        if self.history is None or len(self.history) != (max_iterations + 1) * worlds:
            self.history = wp.zeros((max_iterations + 1) * worlds, dtype=wp.float64, device=shell.device)
            self.forget_graphs()  # the captured loop writes the history array it was captured with
        search = self.search.numpy().reshape(worlds, SEARCH_SIZE)
        search[:, TOL:] = np.column_stack([np.full(worlds, tol), np.full(worlds, max_iterations),
                                           np.broadcast_to(shell.force_scale(), worlds),
                                           np.full(worlds, ENERGY_NOISE[shell.scalar])])
        self.search.assign(search.ravel())

    def solve(self, start: wp.array, out: wp.array, failed: wp.array, counts: wp.array) -> None:
        """A relaxation inside a caller's step (capturable; `prepare` first, no self-contact): from `start` into `out`;
        failed[w] = its status where world w did not converge (BUDGET_SPENT, or NO_DESCENT, a round-off floor, above
        ROUND_OFF_SLACK × tol); counts[2w], counts[2w + 1] += its iterations, 1."""
        wp.copy(self.x, start)
        self._solve()
        wp.copy(out, self.x)
        wp.launch(outcome_kernel, dim=self.shell.worlds, inputs=[self.flags, self.search, wp.float64(ROUND_OFF_SLACK)],
                  outputs=[failed, counts],
                  device=self.shell.device)

    def forget_graphs(self) -> None:
        """Drop the captured loops (they hold the arrays and terms they were captured with)."""
        self._graphs, self._resume_graphs = {}, {}

    def _solve(self) -> None:
        """The whole relaxation: the start, then passes while the line search and the checks go on."""
        self._start()
        wp.capture_while(self.condition, self._pass)

    def _resume(self) -> None:
        wp.launch(resume_kernel, dim=1, outputs=[self.flags, self.condition])
        wp.capture_while(self.condition, self._pass)

    def _start(self) -> None:
        shell, n = self.shell, self.shell.mesh.n_vertices
        shell.forces_device(self.x, self.forces, self.energy)
        self.sums.zero_()
        self.largest.zero_()
        wp.launch(start_kernel, dim=n, inputs=[self.forces, self.inverse_stiffness],
                  outputs=[self.s, self.direction, self.sums, self.largest])  # fmt: skip
        wp.launch(start_search_kernel, dim=shell.worlds, inputs=[self.energy, self.sums, self.largest],
                  outputs=[self.search, self.flags, self.history])  # fmt: skip
        wp.launch(continue_kernel, dim=1, inputs=[self.flags], outputs=[self.condition])

    def _pass(self) -> None:
        """Evaluate x + α d, let the line search decide, and after an accepted step update d."""
        shell, n, worlds = self.shell, self.shell.mesh.n_vertices, self.shell.worlds
        contact = shell.self_contact
        wp.launch(trial_kernel, dim=n, inputs=[self.x, self.direction, self.search], outputs=[self.trial, self.dot, self.flags])
        shell.forces_device(self.trial, self.trial_forces, self.trial_energy)
        if contact is not None:  # a trial half the skin away is refused; once a quarter away, a new search
            contact.mark_moved(self.flags, FAR_TRIAL, OUTSIDE_SKIN)
        wp.launch(slope_kernel, dim=n, inputs=[self.trial_forces, self.direction], outputs=[self.dot])
        wp.launch(line_search_kernel, dim=worlds, inputs=[self.trial_energy, self.dot], outputs=[self.search, self.flags])
        self.sums.zero_()
        self.largest.zero_()
        wp.launch(accept_kernel, dim=n, inputs=[self.flags, self.trial, self.trial_forces, self.inverse_stiffness],
                  outputs=[self.x, self.forces, self.s, self.s_old, self.sums, self.largest])  # fmt: skip
        wp.launch(beta_kernel, dim=worlds, inputs=[self.flags, self.sums], outputs=[self.search])
        wp.launch(direction_kernel, dim=n, inputs=[self.flags, self.s, self.forces, self.search],
                  outputs=[self.direction, self.sums])  # fmt: skip
        wp.launch(iteration_kernel, dim=worlds, inputs=[self.flags, self.sums, self.largest, self.search],
                  outputs=[self.history])  # fmt: skip
        wp.launch(restart_kernel, dim=n, inputs=[self.flags, self.s], outputs=[self.direction])
        wp.launch(continue_kernel, dim=1, inputs=[self.flags], outputs=[self.condition])

    def _loop(self, callback, announce: bool = True) -> None:
        """The loop driven from the host: callback(iteration, E, residual) at the start and after each step."""
        if announce:
            search = self.search.numpy()
            callback(0, search[ENERGY], search[RESIDUAL])
        while self.condition.numpy()[0]:
            self._pass()
            if callback is not None:
                flags, search = self.flags.numpy(), self.search.numpy()
                if flags[ACCEPTED]:
                    callback(int(flags[ITERATION]), search[ENERGY], search[RESIDUAL])

    def _result(self, tol: float, out):
        worlds = self.shell.worlds
        flags, search = self.flags.numpy().reshape(worlds, -1), self.search.numpy().reshape(worlds, -1)
        iterations, statuses, residuals = flags[:, ITERATION], flags[:, STATUS], search[:, RESIDUAL]
        history = self.history.numpy().reshape(worlds, -1)
        histories = [history[w, : iterations[w] + 1].tolist() for w in range(worlds)]
        self.shell.relax_history = histories[0] if worlds == 1 else histories
        self.status = int(statuses[0])
        self.statuses = statuses
        if worlds == 1 and self.status == STALE:
            return None  # relax() searches again and resumes; only the final round's result is read
        if np.all(statuses == CONVERGED):
            if out is None:
                return self.x.numpy().astype(np.float64)
            wp.copy(out, self.x)
            return None
        x = self.x.numpy().astype(np.float64)
        failed = np.flatnonzero(statuses != CONVERGED)
        w = int(failed[np.argmax(residuals[failed])])
        residual, round_off = float(residuals[w]), bool(np.all(statuses[failed] != BUDGET_SPENT))
        where = "" if worlds == 1 else f"in world{'s' * (len(failed) > 1)} {', '.join(map(str, failed))} (the others converged); world {w} "
        raise RelaxationError(
            f"relax stopped {where}after {iterations[w]} iterations at residual max|F|/(Y h ℓ̄) = {residual:.3g}, "
            f"{residual / tol:.3g}× the tolerance {tol:g}"
            + (" (the energy is not finite: the positions hold NaN or Inf)" if not np.isfinite(residual) else
               " (the line search found no lower energy: round-off floor; use dtype='float64' or a larger tol)"
               if round_off else "; raise max_iterations or tol"),  # fmt: skip
            residual, x, round_off=round_off, iterations=int(iterations[w]),
            worlds=None if worlds == 1 else failed.tolist(),
            failures={int(f): (float(residuals[f]), bool(statuses[f] != BUDGET_SPENT)) for f in failed},
        )  # fmt: skip


def checked_method(method: str) -> str:
    """`method` if it is one of METHODS, else ValueError listing them."""
    if method not in METHODS:
        raise ValueError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
    return method


def relax(shell, x: wp.array, tol: float, max_iterations: int, callback=None, out: wp.array | None = None,
          method: str = "ncg", newton_steps: int = NEWTON_STEPS):  # fmt: skip
    """Relax `shell` from positions x (device array) by `method` (Shell.relax); the shell keeps its
    Relaxation and NewtonFinish (buffers, graph, Hessian pattern). Returns the positions (NumPy), or
    writes them to the device array `out` and returns None.

    "auto" hands over to Newton where CG spent its budget or stopped at round-off more than
    ROUND_OFF_SLACK × tol away (nearer is the dtype's floor: it raises), not with self-contact or with `terms`
    that have no `twin` for the float64 Newton shell (RestingGround).
    """
    checked_method(method)
    newton_terms = all(callable(getattr(term, "twin", None)) for term in shell.terms)
    if method == "newton" and not newton_terms:
        raise ValueError("the Newton finish works on the shell's own energy and terms that can be twinned: relax a "
                         "shell with `terms` such as RestingGround by method 'ncg' or 'auto' (which then stays with "
                         "CG)")
    if shell.worlds > 1:  # nonlinear CG per world; the Newton finish works on one world's Hessian
        if method == "newton" or callback is not None:
            raise ValueError(f"batched worlds relax by nonlinear CG without a callback (method 'ncg' or 'auto'), got "
                             f"method={method!r}{' and a callback' if callback is not None else ''}; relax one "
                             "world's own Shell for a Newton finish or a callback")  # fmt: skip
        return _conjugate_gradients(shell, x, tol, max_iterations, None, out)
    if method == "newton":
        return _newton(shell, x.numpy().astype(np.float64), tol, newton_steps, callback, out, [], 0)
    try:
        return _conjugate_gradients(shell, x, tol, max_iterations, callback, out)
    except RelaxationError as error:
        floor = error.round_off and error.residual <= ROUND_OFF_SLACK * tol
        if method == "ncg" or floor or shell.self_contact is not None or not newton_terms:
            raise
        if not np.isfinite(error.residual):  # no Newton step starts from NaN positions
            raise
        history = list(shell.relax_history)
        return _newton(shell, error.x, tol, newton_steps, callback, out, history[:-1], error.iterations)


def _newton(shell, x0: np.ndarray, tol: float, steps: int, callback, out, history: list, iterations: int):
    """The Newton finish (wavewarp/newton.py) from x0; the result as `relax` returns it."""
    if shell._newton is None:
        shell._newton = NewtonFinish(shell)
    x, status, residual, energies = shell._newton.run(x0, tol, steps, callback, iterations)
    shell.relax_history = history + energies
    shell.newton_steps = len(energies) - 1
    if status != "converged":
        raise RelaxationError(
            f"relax stopped after {iterations} CG iterations and {len(energies) - 1} Newton steps at residual "
            f"max|F|/(Y h ℓ̄) = {residual:.3g}, {residual / tol:.3g}× the tolerance {tol:g}"
            + (" (no shift of the Newton step lowers the energy: round-off floor; use a larger tol)"
               if status == "round-off" else "; raise newton_steps or tol"),  # fmt: skip
            residual, x, round_off=status == "round-off", iterations=iterations,
        )  # fmt: skip
    if out is None:
        return x
    out.assign(x.astype(shell._real))
    return None


def _conjugate_gradients(shell, x: wp.array, tol: float, max_iterations: int, callback=None,
                         out: wp.array | None = None):  # fmt: skip
    """Nonlinear CG from x; with self-contact its candidate pairs are searched at x, and again
    wherever the loop stops because the positions left a quarter of the search's skin (STALE);
    the loop then resumes."""
    shell.newton_steps = 0
    if shell._relaxation is None:
        shell._relaxation = Relaxation(shell)
    relaxation, contact = shell._relaxation, shell.self_contact
    if contact is not None:
        contact.search(x)
    result = relaxation.run(x, tol, max_iterations, callback, out)
    while relaxation.status == STALE:
        contact.search(relaxation.x)
        result = relaxation.run(relaxation.x, tol, max_iterations, callback, out, resume=True)
    return result
