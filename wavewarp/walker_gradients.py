"""Walker gradients by central differences over the worlds of one batch (docs/theory/gradients.md, "Walkers").

The objective is the walk itself: the centre of mass's displacement along the wave's direction, in R,
at every chemistry step of the run (its value at the end is J). For each parameter θ and step δ the
batch holds the worlds θ ± δ beside the unperturbed one; they share every chemistry and mechanics
step (the strictest world's), so (J(θ+δ) - J(θ-δ)) / 2δ is the derivative of one discretisation.
The run is in float64. Two steps per parameter measure whether the derivative has converged (their
relative `agreement`), which is what fails past the horizon of a chaotic gait. The wave may depend on
the shape (sensitive walkers): the differences go through the whole coupled run.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

PARAMETERS = ("AC", "AI", "thickness", "young", "mu_v", "elongation")  # the batch's per-world shell and shape parameters
OBJECTIVES = ("distance",)
STEPS = (1e-4, 1e-5)  # relative steps of the central differences (absolute where θ = 0)


class WalkerGradientError(ValueError):
    """A walker gradient that cannot be taken as asked (the message names the fix)."""


def check_walker_differentiable(wrt, objective: str = "distance", steps=STEPS) -> None:
    """Raise WalkerGradientError, naming the fix, where `walker_gradient` cannot be taken."""
    unknown = [name for name in wrt if name not in PARAMETERS]
    if unknown or not wrt:
        raise WalkerGradientError(f"--wrt {','.join(unknown) or '(nothing)'}: a walker's differentiable parameters are "
                                  f"{', '.join(PARAMETERS)}")  # fmt: skip
    if objective not in OBJECTIVES:
        raise WalkerGradientError(f"--objective {objective}: a walker's objectives are {', '.join(OBJECTIVES)}")
    if len(steps) < 1 or any(not 0.0 < step < 0.5 for step in steps):
        raise WalkerGradientError(f"steps {list(steps)}: give one or more relative steps between 0 and 0.5, e.g. 1e-3,1e-4")


def perturbed_worlds(p, wrt, steps) -> list:
    """[(name, δ, sign, parameters)]: the unperturbed world first (name None), then θ ± δ for each parameter
    and step (δ = step × |θ|, or step where θ = 0)."""
    worlds = [(None, 0.0, 0, p)]
    for name in wrt:
        theta = float(getattr(p, name))
        for step in steps:
            delta = step * abs(theta) if theta else step
            worlds += [(name, delta, sign, replace(p, **{name: theta + sign * delta})) for sign in (1, -1)]
    return worlds


def forward_distance(trace: np.ndarray, forward, radius: float) -> np.ndarray:
    """The centre of mass's displacement along `forward` since the trace's first row, in R, at every row
    (rows: t, c at the origin, centre of mass, origin vertex)."""
    com = trace[:, 2:5]
    return (com - com[0]) @ np.asarray(forward, dtype=np.float64) / radius


def walker_gradient(build_batch, p, wrt, *, objective: str = "distance", steps=STEPS, seed: int = 0, device=None,
                    report=print) -> dict:  # fmt: skip
    """dJ/dθ of a walker scene (`build_batch(ps, seeds=, device=, report=)`, a scene module's) at parameters
    `p` for the parameters named in `wrt`, by central differences over one float64 batch.

    Returns {"objective": J at the end, "gradient": {name: dJ/dθ with the smallest step}, "agreement": {name:
    |g(δ₁) - g(δ_k)| / |g(δ_k)|, the largest step against the smallest}, "steps", "deltas": {name: [δ...]},
    "times": chemistry times, "distance": J(t) of the unperturbed world, "derivatives": {name: [dJ/dθ(t)
    per step]}, "period": the unperturbed world's measured period (None if fewer than two pulses),
    "period_kinetic": the FHN kinetics' period, "settle_dt": the mechanics steps the worlds settled and walk with
    (`WalkerRun`'s `mechanics_dt`)}."""
    check_walker_differentiable(wrt, objective, steps)
    p = replace(p, dtype="float64")
    worlds = perturbed_worlds(p, wrt, steps)
    batch = build_batch([q for *_, q in worlds], seeds=[seed] * len(worlds), device=device, report=report)
    results = batch.run()
    stopped = [(w, result["stopped"]) for w, result in enumerate(results) if result["status"] != "done"]
    if stopped:
        w, error = stopped[0]
        raise WalkerGradientError(f"world {w} ({worlds[w][0] or 'unperturbed'}) stopped: {error}; the differences "
                                  "need every world to finish: a smaller step (--set dt=...) or shorter run")  # fmt: skip
    forward = batch.placed[0].forward
    distances = [forward_distance(trace, forward, batch.radius) for trace in batch.traces]
    derivatives, deltas = {name: [] for name in wrt}, {name: [] for name in wrt}
    for w in range(1, len(worlds), 2):
        name, delta, _, _ = worlds[w]
        derivatives[name].append((distances[w] - distances[w + 1]) / (2.0 * delta))
        deltas[name].append(delta)
    gradient = {name: float(series[-1][-1]) for name, series in derivatives.items()}
    agreement = {name: float(abs(series[0][-1] - series[-1][-1]) / max(abs(series[-1][-1]), 1e-300))
                 for name, series in derivatives.items()}  # fmt: skip
    return {"objective": float(distances[0][-1]), "gradient": gradient, "agreement": agreement, "steps": list(steps),
            "deltas": deltas, "times": batch.traces[0][:, 0], "distance": distances[0], "derivatives": derivatives,
            "period": results[0]["measurements"]["period"], "period_kinetic": batch.period_kinetic,
            "settle_dt": batch.settle_dt}  # fmt: skip
