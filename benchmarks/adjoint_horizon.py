"""How the reverse mode's gradient grows with the horizon (issue 31, "chaos, honestly"): on one settled walker with
the insensitive wave (`--set sensitive=true`: the scenes' own, the wave on the deforming shell), the exact derivative of the discrete walk J(T) — the distance along the wave after T — with
respect to the start state (‖dJ/dx₀‖, the walk's sensitivity to where it starts) and to the parameters, at
horizons T from the same settled start, one pass back each. A regular gait's ‖dJ/dx₀‖ grows at most like T; a
chaotic one's like e^{λT}, which fixes the horizon past which a gradient no longer describes the walk's response
to a finite change (docs/studies/2026-11-27-walker-gradient-horizon.md does the same by central differences).

    wavewarp bench adjoint_horizon --device cpu --scene sphere-walker --quick --periods 0.5 1 2 3 4 --out DIR

Writes adjoint_horizon_<scene>_<device>.json and .png (‖dJ/dx₀‖ and |dJ/dθ| against T/T_kinetic, log scale),
with the least-squares growth of ‖dJ/dx₀‖ over the horizons past the first period, as e^{λT} and as T^q.
"""

from __future__ import annotations

import argparse
import os
import sys
from datetime import date

if __package__ in (None, ""):
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import numpy as np  # noqa: E402
import warp as wp  # noqa: E402

from wavewarp.adjoint import ADJOINT_PARAMETERS, WalkAdjoint  # noqa: E402
from wavewarp.device import describe_device, device_tag, resolve_device  # noqa: E402
from wavewarp.io import write_png, write_result  # noqa: E402
from wavewarp.parameters import load_scene, resolve  # noqa: E402

FIXED = ["dtype=float64", "sensitive=false", "mechanics=overdamped", "frames=1"]


def measure(args, device) -> dict:
    module = load_scene(args.scene)
    longest = max(args.periods)
    quick = [f"{name}={value}" for name, value in getattr(module, "QUICK", {}).items()] if args.quick else []
    p = resolve(module.Parameters, None, [*quick, *FIXED, *args.set, f"periods={longest}"])
    run = module.build(p, device=device, report=lambda message: None)
    steps_per_period = run.frames * run.steps_per_frame / longest
    start = [wp.clone(a) for a in run.wave.state.arrays() + [run.dynamics.state.x, run.dynamics.state.v]]
    adjoint, rows = WalkAdjoint(run, args.wrt), []
    for periods in sorted(args.periods):
        for live, saved in zip(run.wave.state.arrays() + [run.dynamics.state.x, run.dynamics.state.v], start):
            wp.copy(live, saved)
        run.shell.update_reference(run.wave.c)
        steps = max(1, round(periods * steps_per_period))
        result = adjoint.gradient(steps)
        start_norm = float(np.linalg.norm(result["start"]["x"]) * run.radius)  # per unit R of displacement
        rows.append({"periods": periods, "steps": steps, "objective": result["objective"],
                     "start_sensitivity": start_norm, "gradient": result["gradient"]})  # fmt: skip
        print(f"T = {periods:g} T_kin (N = {steps}): J = {result['objective']:+.4e} R, ‖dJ/dx₀‖ = {start_norm:.3e}, "
              + ", ".join(f"{name} {value:+.3e}" for name, value in result["gradient"].items()), flush=True)
    return {"scene": module.NAME, "set": [*quick, *FIXED, *args.set], "wrt": list(args.wrt),
            "vertices": run.mesh.n_vertices, "rows": rows, "growth": growth(rows)}  # fmt: skip


def growth(rows) -> dict:
    """Over the horizons of at least one period: λ of ‖dJ/dx₀‖ ∝ e^{λ T} (T in kinetic periods) and the power q of
    ‖dJ/dx₀‖ ∝ T^q, each by least squares (a regular gait: q ≲ 1; a chaotic one: q grows with the span, λ holds)."""
    late = [row for row in rows if row["periods"] >= 1.0]
    if len(late) < 2:
        return {"rate": None, "power": None}
    periods, sizes = np.array([row["periods"] for row in late]), np.log([row["start_sensitivity"] for row in late])
    return {"rate": float(np.polyfit(periods, sizes, 1)[0]), "power": float(np.polyfit(np.log(periods), sizes, 1)[0])}


def chart(result: dict, path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = result["rows"]
    periods = [row["periods"] for row in rows]
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.semilogy(periods, [row["start_sensitivity"] for row in rows], "o-", color="k", label="‖dJ/dx₀‖ R")
    for name in result["wrt"]:
        ax.semilogy(periods, [abs(row["gradient"][name]) for row in rows], ".--", label=f"|dJ/d{name}|")
    fit = result["growth"]
    title = result["scene"] if fit["rate"] is None else (f"{result['scene']}: ‖dJ/dx₀‖ ∝ e^({fit['rate']:.2f} T) or "
                                                        f"T^{fit['power']:.2f} past one period")  # fmt: skip
    ax.set_title(title, fontsize=9)
    ax.set_xlabel("horizon T / T_kinetic")
    ax.set_ylabel("derivative of J(T)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    write_png(fig, path, dpi=110)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="wavewarp bench adjoint_horizon", description=__doc__.split("\n\n")[0])
    parser.add_argument("--device", default=None)
    parser.add_argument("--scene", default="sphere-walker")
    parser.add_argument("--quick", action="store_true", help="the scene's quick mesh")
    parser.add_argument("--periods", type=float, nargs="+", default=[0.5, 1.0, 2.0, 3.0, 4.0],
                        help="horizons, in FHN periods")  # fmt: skip
    parser.add_argument("--wrt", nargs="+", default=["AC", "thickness", "friction", "drag"], choices=ADJOINT_PARAMETERS)
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help="scene parameters")
    parser.add_argument("--out", default=".")
    args = parser.parse_args(argv)
    device = resolve_device(args.device)
    result = {"benchmark": "adjoint_horizon", "date": date.today().isoformat(), **describe_device(device),
              **measure(args, device)}  # fmt: skip
    print(f"growth of ‖dJ/dx₀‖ past one period: {result['growth']}")
    write_result(result, args.out, f"adjoint_horizon_{result['scene']}_{device_tag(device)}", chart)
    return 0


if __name__ == "__main__":
    sys.exit(main())
