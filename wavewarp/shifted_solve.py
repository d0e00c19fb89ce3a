"""(M + s K) x = b on the device by Jacobi-preconditioned conjugate gradients: the implicit diffusion of
the IMEX FitzHugh–Nagumo stepper (wavewarp/waves.py), captured with the step that calls it."""

from __future__ import annotations

import warp as wp

from .kernels.laplace import weighted_dot_kernel
from .kernels.waves import (
    cg_condition_kernel,
    cg_direction_kernel,
    cg_failed_kernel,
    cg_start_kernel,
    cg_step_kernel,
    cg_stop_kernel,
    inverse_diagonal_kernel,
    shifted_operator_kernel,
)
from .laplace import DOT_STRIDE, LaplaceBeltrami


class ShiftedMassSolver:
    """(M + s K) x = b on the device: Jacobi-preconditioned conjugate gradients.

    The loop runs under `wp.capture_while` (device-side exit inside captured graphs) and stops
    when r·P r ≤ tol² b·P b or after `max_iterations`; a miss sets `failed`. Plain kernels with
    strided reductions: Warp's tiled CG reductions cost ~5 ms per dot product on the CPU
    (Warp 1.19, measured), several stiffness actions.
    """

    def __init__(self, operator: LaplaceBeltrami, tol: float, max_iterations: int):
        self.operator, self.tol, self.max_iterations = operator, tol, max_iterations
        n, scalar = operator.n_vertices, operator.scalar
        with wp.ScopedDevice(operator.device):
            self.r, self.z, self.p, self.Ap, self.Kp = (wp.empty(n, dtype=scalar) for _ in range(5))
            self.K_diagonal, self.inverse_diagonal = wp.empty(n, dtype=scalar), wp.empty(n, dtype=scalar)
            self.sums = wp.zeros(5, dtype=scalar)  # r·z, new r·z, p·Ap, b·P b, stop threshold
            self.iteration, self.condition = wp.zeros(1, dtype=wp.int32), wp.zeros(1, dtype=wp.int32)
            self.failed = wp.zeros(1, dtype=wp.int32)
        self.rz, self.rz_new, self.pAp, self.bz, self.rz_stop = (self.sums[i : i + 1] for i in range(5))
        self.shift = None
        self._x = None

    def prepare(self, shift: float) -> None:
        """Set s and the Jacobi preconditioner 1 / (M + s diag K) for the current surface."""
        op = self.operator
        self.shift = op.scalar(shift)
        op.diagonal_device(self.K_diagonal)
        wp.launch(inverse_diagonal_kernel, dim=op.n_vertices, inputs=[op.mass_device, self.K_diagonal, self.shift],
                  outputs=[self.inverse_diagonal], device=op.device)  # fmt: skip

    def _apply(self, x: wp.array, out: wp.array) -> None:
        op = self.operator
        op.apply_device(x, self.Kp)
        wp.launch(shifted_operator_kernel, dim=op.n_vertices, inputs=[x, self.Kp, op.mass_device, self.shift],
                  outputs=[out], device=op.device)  # fmt: skip

    def solve(self, b: wp.array, x: wp.array) -> None:
        """x ← (M + s K)⁻¹ b, starting from x."""
        op, n = self.operator, self.operator.n_vertices
        self._x = x
        self._apply(x, self.Ap)
        wp.launch(cg_start_kernel, dim=n, inputs=[b, self.Ap, self.inverse_diagonal], outputs=[self.r, self.z, self.p],
                  device=op.device)  # fmt: skip
        op.dot_device(self.r, self.z, self.rz)
        self.bz.zero_()
        stride = min(n, DOT_STRIDE)
        wp.launch(weighted_dot_kernel, dim=stride, inputs=[b, b, self.inverse_diagonal, stride], outputs=[self.bz],
                  device=op.device)  # fmt: skip
        wp.launch(cg_stop_kernel, dim=1, inputs=[self.rz, self.bz, op.scalar(self.tol**2)],
                  outputs=[self.rz_stop, self.iteration, self.condition], device=op.device)  # fmt: skip
        wp.capture_while(self.condition, self._iterate)
        wp.launch(cg_failed_kernel, dim=1, inputs=[self.rz, self.rz_stop], outputs=[self.failed], device=op.device)

    def _iterate(self) -> None:
        op, n = self.operator, self.operator.n_vertices
        self._apply(self.p, self.Ap)
        op.dot_device(self.p, self.Ap, self.pAp)
        wp.launch(cg_step_kernel, dim=n, inputs=[self.p, self.Ap, self.inverse_diagonal, self.rz, self.pAp],
                  outputs=[self._x, self.r, self.z], device=op.device)  # fmt: skip
        op.dot_device(self.r, self.z, self.rz_new)
        wp.launch(cg_direction_kernel, dim=n, inputs=[self.z, self.rz, self.rz_new], outputs=[self.p], device=op.device)
        wp.launch(cg_condition_kernel, dim=1, inputs=[self.rz_new, self.rz, self.rz_stop, self.iteration, self.max_iterations],
                  outputs=[self.condition], device=op.device)  # fmt: skip
