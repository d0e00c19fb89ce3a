"""Walkers across mechanical regimes (Fig. 3a; docs/studies/2026-11-27-walker-regime-scans.md): the sphere,
prism and cube twins over seeds in each regime, against the paper's three claims.

    wavewarp bench walker_regimes --device cuda --seeds 8 --periods 4 --out benchmarks/results/regimes
    wavewarp bench walker_regimes --tables benchmarks/results/regimes --device-name "NVIDIA H200"

A regime is a mechanics, a contact solve and a friction law (`REGIMES`; `--regimes` and `--scenes`
pick some, `--pairs REGIME:SCENE ...` exactly those, started in that order). Each regime × scene is one `wavewarp sweep`
(sensitive × seeds, the seeds of one twin one batched run) in OUT/sweeps/REGIME_SCENE, so that a
killed scan run again computes only the seeds it lacks; its table is kept as OUT/REGIME_SCENE.csv.
`--tables DIR` reads such tables instead. Writes
OUT/walker_regimes.json — per regime, scene and twin: n, mean and standard deviation of
speed_R_per_T (the forward displacement per pulse, in R), the share of seeds moving along the wave
and the mean period; per regime and scene the twins' speed ratio (sensitive / insensitive, each seed's
speed per unit time over the first pulses every seed of both twins has where the tables list the pulses,
else the whole runs' per-pulse speeds; its spread from the two standard errors), the ratio of the whole
runs' distances in the same time (start-up and last unfinished pulse included) and the period ratio; and
the paper's three claims — every twin moves along the wave (every pulse, where the tables list them), the
sensitive sphere is faster (by more than two standard errors on every footing: the compared pulses and
the same-time distances, or with --skip-pulses the compared pulses and each half of them; undecided,
null, where they disagree — a gait still changing over the run — or with one seed a twin), the
sensitive prism is more than twice as fast as its twin with both moving forward (with --skip-pulses on
the compared pulses and on each half; undecided where they disagree) — and
OUT/walker_regimes.png.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import csv
import glob
import math
import os
import shutil
import sys
from datetime import date

import dask
import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from distributed import Client  # noqa: E402

from wavewarp.device import describe_device, resolve_device  # noqa: E402
from wavewarp.io import write_png, write_result  # noqa: E402
from wavewarp.sweep import SweepSpec, local_cluster, sweep  # noqa: E402

SCENES = ("sphere-walker", "prism-walker", "cube-walker")
OVERDAMPED = ["mechanics=overdamped", "contact_solve=implicit", "drag=0"]  # drag 2 η_ground, as the committed tables
REGIMES = {
    # inertial, friction a weak viscous drag (the paper's k_f = 0.1)
    "inertial-explicit-kf0.1": ["mechanics=inertial", "contact_solve=explicit", "sharpness=0.1"],
    "inertial-implicit-coulomb": ["mechanics=inertial", "contact_solve=implicit", "sharpness=inf"],
    # overdamped at the default drag ζ = 2 η_ground ≈ 61: ζ / (μ k_f g) from 1.2e4 (k_f = 0.1) to 0 (Coulomb)
    **{f"overdamped-implicit-kf{k}": [*OVERDAMPED, f"sharpness={k}"] for k in ("0.1", "1", "10", "100", "1000", "1e4")},
    "overdamped-implicit-coulomb": [*OVERDAMPED, "sharpness=inf"],  # the scenes' defaults but for ζ (60 there)
    # less drag: is the crawl drag-limited (its speed ∝ 1/ζ) or set by the friction?
    "overdamped-implicit-coulomb-drag20": [*OVERDAMPED, "sharpness=inf", "drag=20"],
    "overdamped-implicit-coulomb-drag6": [*OVERDAMPED, "sharpness=inf", "drag=6"],
    # the drag on the deformation only: the translation is the friction's alone (ζ → 0 for the body's motion)
    "overdamped-implicit-coulomb-body": [*OVERDAMPED, "sharpness=inf", "drag_frame=body"],
    "overdamped-implicit-coulomb-body-drag20": [*OVERDAMPED, "sharpness=inf", "drag_frame=body", "drag=20"],
    # softer shells: the sphere sags about 3%, 5.5%, 8% and 18% of R (1.3% at the default Y = 200)
    "overdamped-implicit-coulomb-young93": [*OVERDAMPED, "sharpness=inf", "young=93", "settle=100"],
    "overdamped-implicit-coulomb-young55": [*OVERDAMPED, "sharpness=inf", "young=55", "settle=100"],
    "overdamped-implicit-coulomb-young34": [*OVERDAMPED, "sharpness=inf", "young=34", "settle=100"],
    "overdamped-implicit-coulomb-young12": [*OVERDAMPED, "sharpness=inf", "young=12", "settle=100"],
    # the prism and cube toward the sphere's sags (the prism sags 0.21% of R at Y = 200, 0.6% at Y = 34)
    "overdamped-implicit-coulomb-young5": [*OVERDAMPED, "sharpness=inf", "young=5", "settle=100"],
    "overdamped-implicit-coulomb-young2": [*OVERDAMPED, "sharpness=inf", "young=2", "settle=100"],
    # the prism between its 2.6% (Y = 5) and 12% (Y = 2) sags, toward 8%
    "overdamped-implicit-coulomb-young3": [*OVERDAMPED, "sharpness=inf", "young=3", "settle=100"],
    "overdamped-implicit-coulomb-young2.5": [*OVERDAMPED, "sharpness=inf", "young=2.5", "settle=100"],
}  # fmt: skip


def run_regime(regime: str, scene: str, args, device: str, executor, priority: int = 0) -> None:
    """The sweep of `scene`'s twins over the seeds in `regime` on `executor` in OUT/sweeps/REGIME_SCENE (the
    seeds done there are skipped; its batches carry the Dask `priority`, higher first), its table kept as
    OUT/REGIME_SCENE.csv."""
    fixed = (f"noise={args.noise}", f"periods={args.periods}", *REGIMES[regime], *args.set)
    spec = SweepSpec(scene, grid={"sensitive": ["true", "false"]}, seeds=args.seeds, fixed=fixed, quick=args.quick,
                     device=device, h5=args.h5)  # fmt: skip
    folder = os.path.join(args.out, "sweeps", f"{regime}_{scene}")
    with dask.annotate(priority=priority):
        sweep(spec, folder, batch=args.seeds, executor=executor, report=lambda line: print(f"{regime} {scene}: {line}"))
    shutil.copy(os.path.join(folder, "table.csv"), os.path.join(args.out, f"{regime}_{scene}.csv"))


def run_regimes(pairs: list, args, device: str) -> None:
    """Every (regime, scene) sweep at once on one local Dask cluster (one worker per GPU, or per core):
    a sweep has only two batches (the twins), so sweeps one after another would leave GPUs idle. The
    batches start in the order of `pairs` (Dask priorities): put the costliest first."""
    with local_cluster(device) as cluster, Client(cluster) as client:
        print(f"Dask: {len(client.scheduler_info()['workers'])} workers; dashboard {client.dashboard_link}")
        executor = client.get_executor()
        with concurrent.futures.ThreadPoolExecutor(len(pairs)) as threads:
            list(threads.map(lambda pair, priority: run_regime(*pair, args, device, executor, priority), pairs,
                             range(len(pairs), 0, -1)))  # raises a sweep's error  # fmt: skip


def pulses(row: dict, name: str = "pulse_displacements_R") -> list:
    """A row's listed measurement `name` (columns NAME_1, NAME_2, ...): by default its forward displacement
    per pulse, in R."""
    out = []
    while row.get(f"{name}_{len(out) + 1}"):
        out.append(float(row[f"{name}_{len(out) + 1}"]))
    return out


def height_drift(rows: list) -> float | None:
    """The mean over seeds of the least-squares slope of the centre's height at the pulses' crossings against
    the pulse count, in R a pulse (None where the tables lack `crossing_heights_R` or a seed has fewer than
    three crossings)."""
    heights = [pulses(r, "crossing_heights_R") for r in rows]
    if not heights or min(map(len, heights)) < 3:
        return None
    return float(np.mean([np.polyfit(np.arange(len(h)), h, 1)[0] for h in heights]))


def distance_by_pulse(rows: list) -> dict | None:
    """Fig. 3a's curve from the pulses: the distance after each of the first k pulses (k the fewest any seed
    has), mean and sd over the seeds, in R (None without pulses)."""
    walks = [np.cumsum(pulses(r)) for r in rows]
    k = min(map(len, walks), default=0)
    if k == 0:
        return None
    walks = np.array([w[:k] for w in walks])
    return {"mean": walks.mean(axis=0).tolist(), "sd": (walks.std(axis=0, ddof=1) if len(walks) > 1 else 0 * walks[0]).tolist()}


def seeds_of(rows: list, sensitive: bool) -> list:
    """The rows of one twin that have a speed (a whole period)."""
    return [r for r in rows if str(r["sensitive"]).lower() == str(sensitive).lower() and r.get("speed_R_per_T")]


def twin(rows: list, sensitive: bool) -> dict:
    """n, speeds, mean, sd, share of seeds moving forward, mean period and (tables that have them) the
    share of all pulses moving forward, the mean rolling angle over the run, in degrees, the mean
    settled sag / R, the centre's `height_drift` and the `distance_by_pulse` of one twin's seeds."""
    chosen = seeds_of(rows, sensitive)
    speeds = [float(r["speed_R_per_T"]) for r in chosen]
    every_pulse = [d for r in chosen for d in pulses(r)]
    n = len(speeds)

    def mean(key):
        values = [float(r[key]) for r in chosen if r.get(key)]
        return float(np.mean(values)) if values else None

    return {"n": n, "speeds": speeds, "mean": float(np.mean(speeds)) if n else None,
            "sd": float(np.std(speeds, ddof=1)) if n > 1 else 0.0,
            "forward_share": sum(s > 0 for s in speeds) / n if n else None,
            "pulse_forward_share": float(np.mean([d > 0 for d in every_pulse])) if every_pulse else None,
            "period": mean("period"), "rolling_angle_deg": mean("rolling_angle_deg"), "sag_R": mean("sag_R"),
            "height_drift_R_per_pulse": height_drift(chosen), "distance_by_pulse_R": distance_by_pulse(chosen)}  # fmt: skip


def compared(rows: list, skip: int = 0, window=None) -> tuple:
    """The twins' per-seed speeds (sensitive, insensitive) on one footing, and its name. The sensitive twin's
    shorter period gives it more whole pulses in the same run, and pulses differ (the first is often the
    largest): where the tables list the pulses, each seed's speed is its mean over its pulses skip + 1 to k,
    k the fewest any seed of either twin has, per unit time (÷ its period); else the whole runs' per-pulse
    speeds. `skip` leaves out the gait's start-up; `window(skip, k)` -> (first, last), 0-based and
    exclusive, picks a part of those pulses instead."""
    sensitive, insensitive = seeds_of(rows, True), seeds_of(rows, False)
    k = min((len(pulses(r)) for r in sensitive + insensitive), default=0)
    if 0 < k <= skip:
        raise ValueError(f"--skip-pulses {skip}: some seed has only {k} whole pulse(s); run more periods")
    first, last = window(skip, k) if window and k else (skip, k)

    def speeds(chosen):
        if k == 0:
            return [float(r["speed_R_per_T"]) for r in chosen]
        return [float(np.mean(pulses(r)[first:last])) / float(r["period"]) for r in chosen]

    footing = (f"pulses {first + 1} to {last} of every seed, per unit time" if first else
               f"first {last} pulse(s) of every seed, per unit time") if k else "whole runs, per pulse"  # fmt: skip
    return speeds(sensitive), speeds(insensitive), footing


HALVES = (lambda skip, k: (skip, (skip + k) // 2), lambda skip, k: ((skip + k) // 2, k))  # earlier, later pulses


def mean_and_error(values: list) -> tuple:
    """Mean and standard error (0 for one value)."""
    return float(np.mean(values)), float(np.std(values, ddof=1) / math.sqrt(len(values))) if len(values) > 1 else 0.0


def twins(rows: list, skip: int = 0) -> dict:
    """Both twins, and the speed ratio sensitive / insensitive (on the footing of `compared`) with its
    first-order spread, the period ratio and (without `skip`, whose point is to leave the start-up out)
    the whole runs' `distances`; with `skip`, the same comparison on each half of the compared pulses
    (`halves`: a gait still changing shows there)."""
    s, i = twin(rows, True), twin(rows, False)
    cell = {"sensitive": s, "insensitive": i, "compared": None, "compared_speeds": None, "speed_ratio": None,
            "speed_ratio_spread": None, "period_ratio": None, "separation": None}  # fmt: skip
    if s["n"] and i["n"]:
        sensitive, insensitive, cell["compared"] = compared(rows, skip)
        cell.update(comparison(sensitive, insensitive), period_ratio=s["period"] / i["period"])
        cell.update(distances(rows) if not skip else {"halves": halves(rows, skip)})
    return cell


def comparison(sensitive: list, insensitive: list) -> dict:
    """Means, their separation in standard errors and their ratio with its first-order spread."""
    (ms, es), (mi, ei) = mean_and_error(sensitive), mean_and_error(insensitive)
    ratio = ms / mi if ms != 0 and mi != 0 else None
    return {"compared_speeds": [ms, mi], "separation": (ms - mi) / math.hypot(es, ei) if es or ei else None,
            "speed_ratio": ratio, "speed_ratio_spread": abs(ratio) * math.hypot(es / ms, ei / mi) if ratio else None}


def halves(rows: list, skip: int) -> list:
    """`comparison` of the twins over the earlier and the later half of the compared pulses (none where they
    are fewer than two)."""
    k = min(len(pulses(r)) for r in seeds_of(rows, True) + seeds_of(rows, False))
    if k - skip < 2:
        return []
    out = []
    for window in HALVES:
        sensitive, insensitive, footing = compared(rows, skip, window)
        out.append({"compared": footing, **comparison(sensitive, insensitive)})
    return out


def distances(rows: list) -> dict:
    """The other footing, where every seed of both twins ran the same time: the whole run's forward distance
    (start-up and the last, unfinished pulse included), its ratio sensitive / insensitive and the separation
    of the twins' means in standard errors. Empty where the tables lack it."""
    chosen = seeds_of(rows, True) + seeds_of(rows, False)
    if not all(r.get("distance_R") and r.get("time") for r in chosen) or len({float(r["time"]) for r in chosen}) != 1:
        return {}
    (ms, es), (mi, ei) = (mean_and_error([float(r["distance_R"]) for r in seeds_of(rows, flag)]) for flag in (True, False))
    return {"distances": [ms, mi], "distance_ratio": ms / mi if mi else None,
            "distance_separation": (ms - mi) / math.hypot(es, ei) if es or ei else None}


def claims(scenes: dict) -> dict:
    """The paper's claims for one regime (None where a scene is missing)."""
    def separated(cell):  # None with fewer than two seeds a twin, or where the footings disagree
        if min(cell["sensitive"]["n"], cell["insensitive"]["n"]) < 2:
            return None
        footings = ((cell["compared_speeds"], cell["separation"]), (cell.get("distances"), cell.get("distance_separation")),
                    *((half["compared_speeds"], half["separation"]) for half in cell.get("halves", ())))  # fmt: skip
        verdicts = {means[0] > 0 and sep > 2 for means, sep in footings if sep is not None}  # faster along the wave
        return verdicts.pop() if len(verdicts) == 1 else None

    complete = [c for c in scenes.values() if c["sensitive"]["n"] and c["insensitive"]["n"]]
    sphere, prism = scenes.get("sphere-walker"), scenes.get("prism-walker")
    def forward(t):  # every pulse where the table lists them, else the whole run
        return t["mean"] > 0 if t["pulse_forward_share"] is None else t["pulse_forward_share"] == 1.0

    return {"forward": all(forward(c[t]) for c in complete for t in ("sensitive", "insensitive")) if complete else None,
            "sensitive_sphere_faster": separated(sphere) if sphere and sphere["sensitive"]["n"] else None,
            "prism_ratio_above_2": prism_faster_twice(prism) if prism and prism["sensitive"]["n"] else None}  # fmt: skip


def prism_faster_twice(cell: dict) -> bool | None:
    """Claim 3 on the twins' compared speeds (`compared`): both move forward and the sensitive twin more than
    twice as fast (a ratio of two backward speeds is no claim); undecided (None) where the halves of the
    compared pulses disagree."""
    if cell["compared_speeds"] is None:  # a twin without a whole period
        return False
    verdicts = {bool(s > 0 and i > 0 and s > 2 * i)
                for s, i in (cell["compared_speeds"], *(half["compared_speeds"] for half in cell.get("halves", ())))}
    return verdicts.pop() if len(verdicts) == 1 else None


def summary(tables: dict, skip: int = 0) -> dict:
    """{regime: {"scenes": {scene: twins}, "claims": ...}} from {(regime, scene): rows}; `skip`: `compared`'s."""
    regimes = {}
    for (regime, scene), rows in tables.items():
        regimes.setdefault(regime, {"scenes": {}})["scenes"][scene] = twins(rows, skip)
    for regime in regimes.values():
        regime["claims"] = claims(regime["scenes"])
    return regimes


def read_tables(folder: str, regimes, scenes) -> dict:
    """{(regime, scene): rows} of the tables REGIME_SCENE.csv in `folder` (those of the regimes and scenes asked for)."""
    tables = {}
    for path in sorted(glob.glob(os.path.join(folder, "*_*.csv"))):
        regime, scene = os.path.basename(path)[:-4].rsplit("_", 1)
        if regime in regimes and scene in scenes:
            with open(path) as f:
                tables[(regime, scene)] = list(csv.DictReader(f))
    return tables


def short(regime: str) -> str:
    return regime.replace("overdamped-implicit-", "overdamped ").replace("inertial-implicit-", "inertial ").replace(
        "inertial-explicit-", "inertial explicit ").replace("coulomb-", "coulomb ")


def scene_panels(result: dict, height: float) -> tuple:
    """(figure, [(axes, scene)]): one panel per scene of `result`."""
    scenes = [s for s in SCENES if any(s in r["scenes"] for r in result["regimes"].values())]
    fig, axes = plt.subplots(1, len(scenes), figsize=(5.0 * len(scenes), height), squeeze=False)
    return fig, list(zip(axes[0], scenes))


def finish_panel(ax, scene: str, linthresh: float, ylabel: str, legend_size: int) -> None:
    ax.axhline(0.0, color="grey", lw=0.8)
    ax.set_yscale("symlog", linthresh=linthresh)
    ax.set_ylabel(ylabel)
    ax.set_title(scene)
    ax.legend(fontsize=legend_size)


def finish_figure(fig, title: str, path: str) -> None:
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    write_png(fig, path, dpi=110)


def chart(result: dict, path: str) -> None:
    fig, panels = scene_panels(result, 5.2)
    for ax, scene in panels:
        regimes = [r for r in REGIMES if r in result["regimes"] and scene in result["regimes"][r]["scenes"]]
        for k, (key, label) in enumerate((("sensitive", "sensitive"), ("insensitive", "insensitive twin"))):
            cells = [(x, result["regimes"][r]["scenes"][scene]) for x, r in enumerate(regimes)]
            cells = [(x + (0.12 if k == 0 else -0.12), c[key]) for x, c in cells if c[key]["n"]]
            ax.errorbar([x for x, _ in cells], [c["mean"] for _, c in cells], yerr=[c["sd"] for _, c in cells], fmt="o",
                        color=f"C{k}", capsize=3, label=f"{label}, mean ± sd")  # fmt: skip
            for x, c in cells:
                ax.plot([x] * c["n"], c["speeds"], ".", color=f"C{k}", alpha=0.35, ms=4)
        ax.set_xticks(range(len(regimes)), [short(r) for r in regimes], fontsize=7, rotation=60, ha="right")
        finish_panel(ax, scene, 1e-4, "speed (R per T, forward = along the wave)", 7)
    finish_figure(fig, f"walkers across regimes, {result['device_name']}", path)


def gaits_chart(result: dict, path: str) -> None:
    """Fig. 3a's form: distance / R against t / T (pulses), sensitive solid, insensitive dashed, ± sd bands."""
    fig, panels = scene_panels(result, 4.4)
    for ax, scene in panels:
        regimes = [r for r in REGIMES if scene in result["regimes"].get(r, {}).get("scenes", {})]
        for k, regime in enumerate(regimes):
            for key, style in (("sensitive", "-"), ("insensitive", "--")):
                walk = result["regimes"][regime]["scenes"][scene][key]["distance_by_pulse_R"]
                if walk is None:
                    continue
                t, mean, sd = np.arange(len(walk["mean"]) + 1), np.r_[0.0, walk["mean"]], np.r_[0.0, walk["sd"]]
                ax.plot(t, mean, style, color=f"C{k % 10}", label=f"{short(regime)}, {key}")
                ax.fill_between(t, mean - sd, mean + sd, color=f"C{k % 10}", alpha=0.2, lw=0)
        ax.set_xlabel("t / T (pulses)")
        finish_panel(ax, scene, 1e-3, "distance / R along the wave, mean ± sd", 6)
    finish_figure(fig, f"walkers pulse by pulse, {result['device_name']}", path)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="wavewarp bench walker_regimes", description=__doc__.splitlines()[0])
    parser.add_argument("--device", default=None)
    parser.add_argument("--regimes", nargs="+", choices=tuple(REGIMES), default=list(REGIMES))
    parser.add_argument("--scenes", nargs="+", choices=SCENES, default=list(SCENES))
    parser.add_argument("--pairs", nargs="+", default=None, metavar="REGIME:SCENE",
                        help="run exactly these (regime, scene) sweeps instead of --regimes × --scenes")
    parser.add_argument("--seeds", type=int, default=8, help="rest shapes per twin (one batched run)")
    parser.add_argument("--noise", type=float, default=1e-3, help="rest-shape noise / R (seeded)")
    parser.add_argument("--periods", type=float, default=4.0)
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help="fixed for every run")
    parser.add_argument("--tables", default=None, metavar="DIR", help="summarise the tables REGIME_SCENE.csv in DIR")
    parser.add_argument("--device-name", default=None, help="with --tables: the GPU or CPU that computed them")
    parser.add_argument("--out", default=None, help="folder for the tables, JSON and chart (default: --tables, else .)")
    parser.add_argument("--skip-pulses", type=int, default=0, metavar="N",
                        help="compare the twins without each seed's first N pulses (the gait's start-up; long runs)")
    parser.add_argument("--quick", action="store_true", help="the scenes' quick runs (a CPU smoke run)")
    parser.add_argument("--h5", action="store_true", help="keep each world's trajectory in its sweep's folder: a batch "
                        "killed part-way goes on from its last stored frame when run again")  # fmt: skip
    args = parser.parse_args(argv)
    if args.skip_pulses < 0:
        parser.error(f"--skip-pulses must be >= 0, got {args.skip_pulses}")
    args.out = args.out or args.tables or "."
    os.makedirs(args.out, exist_ok=True)
    if args.tables is not None:
        if not args.device_name:
            parser.error("--tables needs --device-name (the GPU or CPU that computed them)")
        described = {"device_name": args.device_name}
    else:
        device = resolve_device(args.device)
        pairs = [(r, s) for r in args.regimes for s in args.scenes]
        if args.pairs:
            pairs = [tuple(pair.rsplit(":", 1)) for pair in args.pairs]
            unknown = [":".join(p) for p in pairs if len(p) != 2 or p[0] not in REGIMES or p[1] not in SCENES]
            if unknown:
                parser.error(f"--pairs: {', '.join(unknown)} is not REGIME:SCENE (regimes: {', '.join(REGIMES)}; "
                             f"scenes: {', '.join(SCENES)})")  # fmt: skip
            args.regimes, args.scenes = list(dict.fromkeys(p[0] for p in pairs)), list(dict.fromkeys(p[1] for p in pairs))
        run_regimes(pairs, args, "cuda" if device.is_cuda else "cpu")
        described = describe_device(device)
    tables = read_tables(args.tables or args.out, args.regimes, args.scenes)
    if not tables:
        parser.error(f"no tables REGIME_SCENE.csv for {', '.join(args.regimes)} in {args.tables or args.out}")
    try:
        regimes = summary(tables, args.skip_pulses)
    except ValueError as error:
        parser.error(str(error))
    result = dict(benchmark="walker_regimes", date=date.today().isoformat(), **described, skip_pulses=args.skip_pulses,
                  regimes=regimes)  # fmt: skip
    def speed(twin):
        return "no whole period" if twin["mean"] is None else f"{twin['mean']:+.3g}"

    for regime, cell in result["regimes"].items():
        print(f"{regime}: " + "; ".join(f"{scene} {speed(c['sensitive'])} / {speed(c['insensitive'])} R/T"
                                         for scene, c in cell["scenes"].items()) + f"; claims {cell['claims']}")  # fmt: skip
    write_result(result, args.out, "walker_regimes", chart)
    if any(c[key]["distance_by_pulse_R"] for r in regimes.values() for c in r["scenes"].values()
           for key in ("sensitive", "insensitive")):  # fmt: skip
        gaits_chart(result, os.path.join(args.out, "walker_regimes_gaits.png"))
        print(f"wrote {os.path.join(args.out, 'walker_regimes_gaits.png')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
