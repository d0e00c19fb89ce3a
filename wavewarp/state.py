"""The simulation's state (NVIDIA Newton's vocabulary): what evolves, on one device, apart from the
static model and from the solvers that advance it.

A `State` holds Warp arrays over the control vertices: positions `x` and velocities `v` (vec3),
control concentrations `c`, their rate `rate` (the telegraph leapfrog's c_t at t − dt/2) or the
inhibitor `w` (FitzHugh–Nagumo), and `history`: named arrays a solver carries from step to step
(FitzHugh–Nagumo's flip detector and the amount its reaction has produced). Fields a run does not
use are None. Solvers advance the arrays with `step(state_in, state_out, dt)`, device work only (so
a CUDA graph can capture it); `time` and `steps` count the chemistry clock, which the guarded runner
(wavewarp/runner.py) advances after each chunk of steps.
"""

from __future__ import annotations

import numpy as np
import warp as wp

FIELDS = ("x", "v", "c", "rate", "w")
# each field's series in an HDF5 trajectory's frames (wavewarp/trajectory.py)
SERIES = {"x": "positions", "v": "velocities", "c": "concentration", "rate": "concentration_rate", "w": "inhibitor"}


class State:
    """Arrays x, v, c, rate, w (each a wp.array or None), `history` {name: wp.array}, time and steps."""

    def __init__(self, *, x=None, v=None, c=None, rate=None, w=None, history=None, time: float = 0.0,
                 steps: int = 0):  # fmt: skip
        self.x, self.v, self.c, self.rate, self.w = x, v, c, rate, w
        self.history = dict(history or {})
        self.time, self.steps = float(time), int(steps)

    def arrays(self) -> list:
        """Every array the state holds (fields then history), in a fixed order: what a guarded run backs up."""
        return [a for a in (getattr(self, name) for name in FIELDS) if a is not None] + list(self.history.values())

    def clone(self) -> State:
        """A deep copy on the same device."""
        copy = {name: None if getattr(self, name) is None else wp.clone(getattr(self, name)) for name in FIELDS}
        return State(**copy, history={k: wp.clone(a) for k, a in self.history.items()}, time=self.time, steps=self.steps)

    def assign(self, other: State) -> None:
        """Copy `other`'s arrays, time and steps into this state's arrays (device to device)."""
        for mine, theirs in zip(self.arrays(), other.arrays()):
            wp.copy(mine, theirs)
        self.time, self.steps = other.time, other.steps

    def numpy(self, name: str) -> np.ndarray:
        """A field as float64 NumPy (x, v: (V, 3); c, rate, w: (V,))."""
        return getattr(self, name).numpy().astype(np.float64)

    def to_frame(self) -> dict:
        """The state's fields as a trajectory frame: {series name: float64 NumPy} (positions, velocities,
        concentration, concentration_rate, inhibitor: those the state holds)."""
        return {series: self.numpy(name) for name, series in SERIES.items() if getattr(self, name) is not None}

    def assign_frame(self, frame: dict) -> None:
        """Set the fields the state holds from a trajectory frame (a resume), and `time` if the frame has it."""
        for name, series in SERIES.items():
            if getattr(self, name) is not None:
                self.set(name, frame[series])
        if "time" in frame:
            self.time = float(frame["time"])

    def set(self, name: str, values) -> None:
        """Overwrite a field (or a history array) from NumPy values, converted to its dtype."""
        array = getattr(self, name) if name in FIELDS else self.history[name]
        real = np.float32 if getattr(array.dtype, "_wp_scalar_type_", array.dtype) == wp.float32 else np.float64
        array.assign(np.asarray(values).astype(real))
