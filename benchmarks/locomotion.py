"""Locomotion benchmark (issue 6; paper Fig. 3a): how fast the walkers walk, sensitive against insensitive.

    wavewarp bench locomotion --device cuda --out benchmarks/results [--quick] [--periods N] [--set NAME=VALUE]
                              [--scenes sphere-walker prism-walker] [--twins both|sensitive|insensitive]

Runs the sphere and prism walkers, each deformation-sensitive and -insensitive (the twin whose
wave runs on the rest shell), over `--periods` FHN periods (default 6) at the scenes' defaults
(`--set` overrides apply to every run). Writes locomotion.json: the device, the date, the twins' ratios per scene
(`twins`: T and the first front's mean arrival, sensitive over insensitive; the speed, insensitive
over sensitive) and a list of runs with `scene`, `sensitive`, `period` (T, measured),
`speed_R_per_T`, `distance_R`, `pulse_displacements_R`, `pulse_alignment`, `lateral_R`, `sag_R`,
`first_front_mean_arrival`, `total_concentration_error`, the resolved parameters and the wall time; and locomotion.png, the forward displacement in R against t/T (Fig. 3a: sensitive
solid, insensitive dashed). `--quick`: coarse meshes over 2.2 periods (a CPU smoke run).
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from datetime import date

SCENES = ("sphere-walker", "prism-walker")
QUICK = {"sphere-walker": ["level=2"], "prism-walker": ["divisions=4"]}


def run_walker(scene: str, sensitive: bool, *, device, periods: float, overrides=()) -> tuple:
    """One walker run through the scene API; returns (summary, trace)."""
    from wavewarp.parameters import load_scene, resolve

    module = load_scene(scene)
    p = resolve(module.Parameters, None, [*overrides, f"sensitive={str(sensitive).lower()}", f"periods={periods}"])
    start = time.perf_counter()
    run = module.build(p, device=device, report=lambda message: None)
    run.record(run.time, run.frame())
    for _ in range(run.frames):
        run.advance_frame()
        run.record(run.time, run.frame())
    summary = {"scene": scene, "sensitive": sensitive, **run.measurements(), "wall_time_s": time.perf_counter() - start,
               "parameters": run.resolved}  # fmt: skip
    return summary, run


def twin_ratios(pair: list) -> dict:
    """Sensitive over insensitive: the period T, the first front's mean arrival over the shell (the
    mechanical feedback on the wave) and, insensitive over sensitive, the speed (Fig. 3a's ratio)."""
    runs = {r["sensitive"]: r for r in pair}
    if set(runs) != {True, False}:
        return {}

    def ratio(name, top, bottom):
        a, b = runs[top].get(name), runs[bottom].get(name)
        return a / b if a is not None and b else None

    return {"period_sensitive_over_insensitive": ratio("period", True, False),
            "arrival_sensitive_over_insensitive": ratio("first_front_mean_arrival", True, False),
            "speed_insensitive_over_sensitive": ratio("speed_R_per_T", False, True)}  # fmt: skip


def main(argv=None) -> int:
    import warp as wp

    from wavewarp.device import resolve_device
    from wavewarp.io import write_json
    from wavewarp.figures import locomotion_png

    parser = argparse.ArgumentParser(prog="wavewarp bench locomotion", description=__doc__.split("\n")[0])
    parser.add_argument("--device", default=None, help="cpu, cuda, cuda:N (default: CUDA when present)")
    parser.add_argument("--out", default=".", help="folder for locomotion.json and locomotion.png")
    parser.add_argument("--periods", type=float, default=None, help="run length in FHN periods (default 6; --quick 2.2)")
    parser.add_argument("--quick", action="store_true", help="coarse meshes over 2.2 periods (a CPU smoke run)")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help="override for every run")
    parser.add_argument("--scenes", nargs="+", choices=SCENES, default=list(SCENES), help="walkers to run (default both)")
    parser.add_argument("--twins", choices=("both", "sensitive", "insensitive"), default="both",
                        help="which of the twins to run (default both)")
    args = parser.parse_args(argv)
    wp.config.log_level = wp.LOG_WARNING
    device = resolve_device(args.device)
    periods = args.periods or (2.2 if args.quick else 6.0)
    os.makedirs(args.out, exist_ok=True)
    runs, lines = [], []
    twins = {"both": (True, False), "sensitive": (True,), "insensitive": (False,)}[args.twins]
    for scene in args.scenes:
        for sensitive in twins:
            overrides = (QUICK[scene] if args.quick else []) + args.set
            summary, run = run_walker(scene, sensitive, device=str(device), periods=periods, overrides=overrides)
            runs.append(summary)
            lines.append((scene, sensitive, run.trace, run.forward, run.radius))
            speed = summary["speed_R_per_T"]
            print(f"{scene:14s} {'sensitive' if sensitive else 'insensitive':11s} T = {summary['period'] or float('nan'):7.2f}"
                  f"  speed = {speed if speed is not None else float('nan'):+.4f} R/T  distance = {summary['distance_R']:+.4f} R"
                  f"  ({summary['wall_time_s']:.1f} s)", flush=True)  # fmt: skip
    twins_measured = {scene: twin_ratios([r for r in runs if r["scene"] == scene]) for scene in args.scenes}
    for scene, ratios in twins_measured.items():
        if ratios:
            print(f"{scene}: " + ", ".join(f"{name} {value:.4f}" for name, value in ratios.items() if value is not None))
    result = {"benchmark": "locomotion", "device": str(device), "device_name": wp.get_device(device).name,
              "host": platform.node(), "date": date.today().isoformat(), "quick": args.quick, "periods": periods,
              "twins": twins_measured, "runs": runs}  # fmt: skip
    write_json(os.path.join(args.out, "locomotion.json"), result)
    locomotion_png(lines, os.path.join(args.out, "locomotion.png"),
                   title=f"walkers, {wp.get_device(device).name}: displacement against time (Fig. 3a)")  # fmt: skip
    print(f"wrote {os.path.join(args.out, 'locomotion.json')} and locomotion.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
