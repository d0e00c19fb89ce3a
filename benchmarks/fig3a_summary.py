"""Fig. 3a's ensembles over seeds: the paper's three claims at t/T = 4, 6 and 12, and the chart (benchmarks/fig3a.py).

A twin's ensemble is its finished runs (status "done") of one regime and scene; each claim compares ensemble means
± one standard deviation (sd 0 for a single seed) of the displacement from t = 0 along the wave, in R, at t/T = k:

* `each_pulse_forward`: every walker's (sphere and prism, both twins) pulses 1 … k go along the wave. Holds where
  every pulse's mean − sd > 0; fails where some pulse's mean + sd < 0; undecided between ("small" is not judged).
* `sensitive_sphere_farther`: the sensitive sphere's displacement at t/T = k beyond its twin's. Holds where the
  bands are apart with the sensitive one ahead; fails where apart the other way; undecided where they overlap.
* `insensitive_prism_under_half`: the insensitive prism's speed (its displacement at k over k periods) under half
  the sensitive one's. Holds where the sensitive prism's mean − sd is positive and the insensitive one's mean + sd
  lies below half of it; fails where the sensitive prism's mean + sd is not positive or the insensitive one's
  mean − sd lies above half the sensitive one's mean + sd; undecided between.

Evaluated at CHECKPOINTS and at the bench's --periods. A check point no ensemble reaches (runs shorter than k
periods, or no finished run) is "not run".
"""

from __future__ import annotations

import numpy as np

CHECKPOINTS = (4, 6, 12)
CLAIMS = {
    "each_pulse_forward": "each pulse leads to a small net displacement of the shell in the direction of the wave",
    "sensitive_sphere_farther": "the deformation-sensitive sphere walks farther than its insensitive twin",
    "insensitive_prism_under_half": "the insensitive prism walks at less than half the sensitive prism's speed",
}
COLOURS = {"sphere-walker": "tab:blue", "prism-walker": "tab:red"}  # the paper's


def ensemble(runs: list, regime: str, scene: str, sensitive: bool) -> list:
    return [r for r in runs if r["status"] == "done" and r["regime"] == regime and r["scene"] == scene
            and r["sensitive"] == sensitive]


def statistics(values: list) -> dict:
    return {"n": len(values), "mean": float(np.mean(values)),
            "sd": float(np.std(values, ddof=1)) if len(values) > 1 else 0.0}


def displacement_at(run: dict, k: float) -> float | None:
    """The run's displacement from t = 0 at t/T = k, in R (None where the run ends before)."""
    if run["t_over_T"][-1] < k - 1e-9:
        return None
    return float(np.interp(k, run["t_over_T"], run["displacement_R"]))


def distance(runs: list, k: float) -> dict | None:
    """Mean and sd over an ensemble of the displacement at t/T = k (None where a run ends before or none ran)."""
    values = [displacement_at(r, k) for r in runs]
    return statistics(values) if values and None not in values else None


def pulses(runs: list, k: int) -> list | None:
    """Mean and sd over an ensemble of each of the pulses 1 … k (None where a run has fewer or none ran)."""
    if not runs or min(len(r["pulse_displacements_R"]) for r in runs) < k:
        return None
    return [statistics([r["pulse_displacements_R"][j] for r in runs]) for j in range(k)]


def each_pulse_forward(runs: list, regime: str, k: int) -> dict:
    walkers = {}
    for scene in COLOURS:
        for sensitive in (True, False):
            chosen = ensemble(runs, regime, scene, sensitive)
            if chosen:
                walkers[f"{scene} {'sensitive' if sensitive else 'insensitive'}"] = pulses(chosen, k)
    if not walkers or None in walkers.values():
        return {"verdict": "not run"}
    every = [p for listed in walkers.values() for p in listed]
    verdict = ("holds" if all(p["mean"] - p["sd"] > 0 for p in every) else
               "fails" if any(p["mean"] + p["sd"] < 0 for p in every) else "undecided")
    return {"verdict": verdict, "walkers": {name: {"n": listed[0]["n"], "mean_R": [p["mean"] for p in listed],
                                                   "sd_R": [p["sd"] for p in listed]}
                                            for name, listed in walkers.items()}}


def twins_at(runs: list, regime: str, scene: str, k: int) -> tuple:
    return (distance(ensemble(runs, regime, scene, True), k), distance(ensemble(runs, regime, scene, False), k))


def sensitive_sphere_farther(runs: list, regime: str, k: int) -> dict:
    s, i = twins_at(runs, regime, "sphere-walker", k)
    if s is None or i is None:
        return {"verdict": "not run"}
    verdict = ("holds" if s["mean"] - s["sd"] > i["mean"] + i["sd"] else
               "fails" if s["mean"] + s["sd"] < i["mean"] - i["sd"] else "undecided")
    ratio = s["mean"] / i["mean"] if i["mean"] else None
    return {"verdict": verdict, "sensitive_R": s, "insensitive_R": i, "ratio_of_means": ratio}


def insensitive_prism_under_half(runs: list, regime: str, k: int) -> dict:
    s, i = twins_at(runs, regime, "prism-walker", k)
    if s is None or i is None:
        return {"verdict": "not run"}
    low, high = s["mean"] - s["sd"], s["mean"] + s["sd"]
    verdict = ("holds" if low > 0 and i["mean"] + i["sd"] < 0.5 * low else
               "fails" if high <= 0 or i["mean"] - i["sd"] > 0.5 * high else "undecided")
    ratio = i["mean"] / s["mean"] if s["mean"] else None
    return {"verdict": verdict, "sensitive_R_per_T": {**s, "mean": s["mean"] / k, "sd": s["sd"] / k},
            "insensitive_R_per_T": {**i, "mean": i["mean"] / k, "sd": i["sd"] / k},
            "insensitive_over_sensitive": ratio}


def claims(runs: list, regimes: list, checkpoints=CHECKPOINTS) -> dict:
    """Per claim: its text and, per regime, one evaluation at each t/T of `checkpoints` with its verdict."""
    judges = {"each_pulse_forward": each_pulse_forward, "sensitive_sphere_farther": sensitive_sphere_farther,
              "insensitive_prism_under_half": insensitive_prism_under_half}
    return {name: {"claim": CLAIMS[name],
                   "regimes": {regime: [{"t_over_T": k, **judge(runs, regime, k)} for k in checkpoints]
                               for regime in regimes}}
            for name, judge in judges.items()}


def band(chosen: list) -> tuple:
    """(t/T grid, mean, sd) of an ensemble's displacement, up to where its shortest run ends."""
    end = min(r["t_over_T"][-1] for r in chosen)
    grid = np.linspace(0.0, end, 241)
    values = np.array([np.interp(grid, r["t_over_T"], r["displacement_R"]) for r in chosen])
    sd = values.std(axis=0, ddof=1) if len(chosen) > 1 else np.zeros_like(grid)
    return grid, values.mean(axis=0), sd


def fig3a_png(runs: list, regimes: list, scenes: list, path: str, title: str) -> None:
    """Like the paper's Fig. 3a: displacement / R against t/T, each twin's mean ± sd over its seeds (sensitive: full
    circles, solid; insensitive: hollow, dashed), the sphere blue and the prism red; one panel per scene and one row
    per regime."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from wavewarp.io import write_png

    fig, axes = plt.subplots(len(regimes), len(scenes), figsize=(5.0 * len(scenes), 2.8 * len(regimes)),
                             squeeze=False)
    for row, regime in enumerate(regimes):
        for column, scene in enumerate(scenes):
            ax, colour = axes[row][column], COLOURS[scene]
            for sensitive in (True, False):
                chosen = ensemble(runs, regime, scene, sensitive)
                if not chosen:
                    continue
                grid, mean, sd = band(chosen)
                whole = np.arange(np.floor(grid[-1] + 1e-9) + 1)
                label = f"{'sensitive' if sensitive else 'insensitive'} (n = {len(chosen)})"
                ax.plot(grid, mean, "-" if sensitive else "--", color=colour, label=label)
                ax.fill_between(grid, mean - sd, mean + sd, color=colour, alpha=0.25 if sensitive else 0.12, lw=0)
                ax.plot(whole, np.interp(whole, grid, mean), "o", color=colour,
                        markerfacecolor=colour if sensitive else "white")
            if ax.has_data():
                ax.legend(fontsize=7, loc="upper left")
            else:
                ax.text(0.5, 0.5, "no finished runs", ha="center", va="center", transform=ax.transAxes)
            ax.set_title(f"{regime}: {scene}", fontsize=9)
            ax.set_xlabel("t / T")
            ax.set_ylabel("displacement / R")
            ax.grid(alpha=0.3)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    write_png(fig, path)
