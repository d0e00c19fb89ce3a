"""Measurements of the chemical over a run: its balance (docs/theory/chemistry.md), the total C = ∫ c dω against
what the equation alone gives, with the smallest concentration; and the first front's arrival.

A wave scene records every frame it writes (or reads back on resume). C is Σ M_I c_I with the
lumped mass of the surface the wave runs on: the frame's positions for a deformation-sensitive run,
the rest surface for the insensitive twin. The expected total comes from the scene: the telegraph
invariant (`waves.telegraph_total`) or, for FitzHugh–Nagumo, C(0) plus the amount the reaction
added (`FitzHughNagumo.produced`, stored with each frame).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .kernels.waves import count_step_kernel, first_crossing_kernel
from .laplace import LaplaceBeltrami


class ChemicalBalance:
    """`total_concentration_error`: the largest |C − C_expected| / max(|C_expected|, ∫|c| dω) over the
    recorded frames (relative to the chemical present); `min_concentration`: the field's smallest value
    at the limit points of the control vertices over them (the control values themselves swing wider:
    the basis smooths them), and its time. `sensitive=False` measures C on the rest surface (the twin's wave never moves).
    On batched worlds (`Mesh.union`) each world is measured apart: `expected_total` one per world."""

    def __init__(self, mesh, *, sensitive: bool, rule: str = "3", device=None, dtype="float32"):
        self._meter = LaplaceBeltrami(mesh, rule=rule, assembled=False, device=device, dtype=dtype)
        self.rest_mass = self._meter.mass()
        self.sensitive = bool(sensitive)
        self.worlds = mesh.worlds
        self.error = np.zeros(self.worlds)
        self.min_concentration, self.min_time = np.full(self.worlds, np.inf), [None] * self.worlds
        self.min_area_ratio = np.full(self.worlds, np.inf)
        self.frame_minima = []  # per recorded frame: (time, each world's smallest field value)

    def record(self, time: float, positions, concentration, expected_total) -> None:
        c = np.asarray(concentration, dtype=np.float64)
        self._meter.update(np.asarray(positions, dtype=np.float64))
        shell_mass = self._meter.mass()
        mass = shell_mass if self.sensitive else self.rest_mass  # the surface the wave runs on
        field = self._meter.field_values(c)
        expected = np.broadcast_to(np.asarray(expected_total, dtype=np.float64), (self.worlds,))
        n = len(c) // self.worlds
        self.frame_minima.append((float(time), field.reshape(self.worlds, n).min(axis=1)))
        for w in range(self.worlds):
            world = slice(w * n, (w + 1) * n)
            ratio = float(np.min(shell_mass[world] / self.rest_mass[world]))
            self.min_area_ratio[w] = min(self.min_area_ratio[w], ratio)
            scale = max(abs(expected[w]), float(mass[world] @ np.abs(c[world])), np.finfo(float).tiny)
            self.error[w] = max(self.error[w], abs(float(mass[world] @ c[world]) - expected[w]) / scale)
            if field[world].min() < self.min_concentration[w]:
                self.min_concentration[w], self.min_time[w] = float(field[world].min()), float(time)

    def measurements(self, world: int = 0) -> dict:
        """World `world`'s; also `min_area_ratio`, the smallest M_I(x) / M_I(rest) over the frames: where
        the shell contracted most (conserving the chemical, a quasi-static shell loses its equilibrium
        near 1/e: docs/theory/transport.md)."""
        recorded = self.min_time[world] is not None
        return {"total_concentration_error": float(self.error[world]) if recorded else None,
                "min_concentration": float(self.min_concentration[world]) if recorded else None,
                "min_concentration_time": self.min_time[world],
                "min_area_ratio": float(self.min_area_ratio[world]) if recorded else None}  # fmt: skip

    def min_concentration_between(self, start: float, end: float, world: int = 0) -> float | None:
        """World `world`'s smallest field value over the recorded frames with start <= time <= end (None if none)."""
        values = [minima[world] for time, minima in self.frame_minima if start <= time <= end]
        return float(min(values)) if values else None


class FirstArrival:
    """Per vertex, when c first reached `level` (the first front's arrival), recorded on the device
    after every step (`launch`, capturable): the step of the crossing, read as its midpoint time
    (n − ½) dt; 0 where c0 already reached it, −1 where no front has arrived yet."""

    def __init__(self, c0: np.ndarray, *, level: float = 0.5, device=None, scalar=wp.float32):
        self.level = scalar(level)
        self.step = wp.zeros(1, dtype=wp.int32, device=device)
        self.first_step = wp.array(np.where(np.asarray(c0) >= level, 0, -1).astype(np.int32), device=device)

    def launch(self, c: wp.array) -> None:
        wp.launch(count_step_kernel, dim=1, outputs=[self.step], device=c.device)
        wp.launch(first_crossing_kernel, dim=len(c), inputs=[c, self.level, self.step], outputs=[self.first_step],
                  device=c.device)  # fmt: skip

    def times(self, dt: float) -> np.ndarray:
        step = self.first_step.numpy()
        return np.where(step > 0, (step - 0.5) * dt, np.where(step == 0, 0.0, -1.0))

    def restore(self, times: np.ndarray, steps: int, dt: float) -> None:
        """Continue from stored arrival `times` at step `steps` (a resumed run)."""
        times = np.asarray(times, dtype=np.float64)
        step = np.where(times > 0, np.round(times / dt + 0.5), np.where(times == 0, 0, -1))
        self.first_step.assign(step.astype(np.int32))
        self.step.fill_(int(steps))


def arrival_measurements(times: np.ndarray) -> dict:
    """The first front over the shell: its mean arrival time over the vertices and when it had reached
    them all (None while some vertex has not seen it)."""
    reached = bool(np.all(times >= 0))
    return {"first_front_mean_arrival": float(np.mean(times)) if reached else None,
            "first_front_last_arrival": float(np.max(times)) if reached else None}  # fmt: skip
