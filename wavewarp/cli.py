"""Command line: `wavewarp list`, `wavewarp run`, `wavewarp render`, `wavewarp bench`: argument parsing
only; the work is the driver's (wavewarp/driver.py), the renderer's and the benchmarks'."""

from __future__ import annotations

import argparse
import importlib
import json
import os
import signal
import sys
import threading
import time

import warp as wp

from wavewarp.benchmarks import NAMES as BENCHMARKS

from .version import __version__
from .driver import interrupt_signal, terminate
from .device import resolve_device
from .gradients import OBJECTIVES, PARAMETERS, check_differentiable, scene_gradient
from .walker import WalkerParameters
from .walker_gradients import OBJECTIVES as WALKER_OBJECTIVES, PARAMETERS as WALKER_PARAMETERS, STEPS as WALKER_STEPS
from .walker_gradients import AGREEMENT, WalkerGradientError, walker_gradient
from .adjoint import ADJOINT_PARAMETERS, walker_adjoint_gradient
from .mesh import cube, icosphere, load, prism
from .parameters import help_lines, load_scene, resolve, scene_descriptions
from .precompile import precompile
from .relax import RelaxationError
from .sizing import check_run_size
from .sweep import SweepSpec, local_cluster, parse_grid, sweep
from .render import render
from .run_command import scene_run
from .waves import BlowUpError


def _list(args) -> int:
    for name, description in scene_descriptions().items():
        print(f"{name:20s} {description}")
    return 0


def _sweep(args) -> int:
    wp.config.log_level = wp.LOG_WARNING
    if args.device is not None:
        resolve_device(args.device)  # as `run` does: no --device cuda without a GPU
    spec = SweepSpec(args.scene, grid=parse_grid(args.grid), seeds=args.seeds, first_seed=args.first_seed,
                     fixed=tuple(args.set), quick=args.quick, device=args.device, h5=args.h5, measure=args.measure,
                     deterministic=args.deterministic)  # fmt: skip
    start = time.perf_counter()

    def report(message):
        print(f"wavewarp sweep {args.scene}: {message}", file=sys.stderr)

    rows = sweep(spec, args.out, batch=args.batch, workers=args.workers, scheduler=args.scheduler,
                 progress=sys.stderr.isatty(), report=report)  # fmt: skip
    for point, error in rows.failures.items():
        report(f"point {point} failed: {' '.join(str(error).split())}")
    if args.json:
        print(json.dumps(rows.summary()))
    else:
        counts = {status: sum(row["status"] == status for row in rows) for status in ("done", "stopped", "failed")}
        print(f"{len(rows)} points in {args.out} ({', '.join(f'{n} {s}' for s, n in counts.items())}): table.csv, "
              f"chart.png ({time.perf_counter() - start:.1f} s); this sweep computed {rows.computed}, skipped "
              f"{rows.skipped}, failed {len(rows.failures)}")
    return 1 if rows.failures else 0


def _cluster(args) -> int:
    """A local Dask cluster kept running for sweeps (`--scheduler ADDRESS`) until interrupted: its workers
    start, import and load their kernels once, not once per sweep."""
    wp.config.log_level = wp.LOG_WARNING
    if args.device is not None:
        resolve_device(args.device)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    with local_cluster(args.device, args.workers, args.port) as cluster:
        print(f"wavewarp cluster: {len(cluster.workers)} workers; scheduler {cluster.scheduler_address}; dashboard "
              f"{cluster.dashboard_link}\nrun sweeps with --scheduler {cluster.scheduler_address}; stop with Ctrl-C",
              flush=True)  # fmt: skip
        try:
            stop.wait()
        except KeyboardInterrupt:
            pass
    print("wavewarp cluster: stopped; the workers' compiled kernels are in this machine's Warp cache")
    return 0


def _precompile(args) -> int:
    """Every kernel module compiled for the CUDA architectures `--arch` into the kernel cache (`--cache`)."""
    bad = [arch for arch in args.arch if not 50 <= arch <= 200]
    if bad:
        raise ValueError(f"--arch {' '.join(map(str, bad))}: give compute capabilities × 10, e.g. 90 for an H100 or H200")
    if args.cache is not None:  # read when Warp starts, as on the GPU machines
        os.environ["WARP_CACHE_PATH"] = args.cache
    start = time.perf_counter()
    paths = precompile(args.arch)
    print(f"{len(paths)} cubins in {wp.config.kernel_cache_dir} ({time.perf_counter() - start:.0f} s); give the GPU "
          "machines this cache (WARP_CACHE_PATH) and they load the kernels instead of compiling them")  # fmt: skip
    return 0


def _build_mesh(args):
    if args.mesh == "icosphere":
        check_run_size("--level", args.level, icosphere, device=args.device)
        mesh = icosphere(args.size, args.level)
    elif args.mesh in ("cube", "prism"):
        generator = {"cube": cube, "prism": prism}[args.mesh]
        check_run_size("divisions (2 × --level)", 2 * max(args.level, 1), generator, device=args.device)
        mesh = generator(args.size, 2 * max(args.level, 1))
    else:
        mesh = load(args.mesh)
    if mesh.needs_refinement:
        print(f"{args.mesh}: a triangle touches two extraordinary vertices; refined once by Loop subdivision", file=sys.stderr)
        mesh = mesh.refined_for_patches()
    return mesh


def _render(args) -> int:
    wp.config.log_level = wp.LOG_WARNING
    summary = render(_build_mesh(args), args.out, rule=args.rule, device=args.device, dtype=args.dtype, name=args.mesh,
                     surface=args.usd_surface, bake_levels=args.usd_bake_levels)  # fmt: skip
    if args.json:
        print(json.dumps(summary))
    else:
        print(f"wrote {args.out}: {summary['triangles']} triangles, limit-surface area {summary['area']:.6g}, "
              f"Gauss-Bonnet error {summary['gauss_bonnet_error']:.2e} ({summary['wall_time_s']:.1f} s)")  # fmt: skip
    return 0


def _bench(args) -> int:
    if args.name not in BENCHMARKS:
        raise ValueError(f"unknown benchmark {args.name!r}; valid: {', '.join(BENCHMARKS)}")
    return importlib.import_module(f"wavewarp.benchmarks.{args.name}").main(args.options)


def scene_epilog(argv) -> str | None:
    """For `wavewarp run SCENE --help`: that scene's parameters with their defaults and meaning."""
    if len(argv) < 2 or argv[0] != "run" or not {"-h", "--help"} & set(argv):
        return None
    scene = next((word for word in argv[1:] if not word.startswith("-")), None)
    try:
        module = load_scene(scene) if scene else None
    except ValueError:
        return None
    if module is None:
        return None
    lines = "\n".join(f"  {line}" for line in help_lines(module.Parameters))
    quick = ", ".join(f"{k}={v}" for k, v in getattr(module, "QUICK", {}).items())
    return (f"{module.NAME}: {getattr(module, 'DESCRIPTION', '')}\n\nits parameters (--set NAME=VALUE; "
            f"NAME=auto where a value is automatic):\n{lines}" + (f"\n\n--quick sets {quick}" if quick else ""))  # fmt: skip


def _port(text: str) -> int:
    if not text.isdigit() or int(text) > 65535:
        raise argparse.ArgumentTypeError(f"must be a port number from 0 to 65535 (0: any free one), got {text!r}")
    return int(text)


def _refinements(text: str) -> int:
    if not text.isdigit() or int(text) < 1:
        raise argparse.ArgumentTypeError(f"must be an integer >= 1, got {text!r}")
    return int(text)


def _deterministic_argument(command) -> None:
    command.add_argument("--deterministic", action="store_true",
                         help="bit-exact repeated runs on a GPU (Warp's deterministic atomics; slower)")  # fmt: skip


def _usd_arguments(command) -> None:
    command.add_argument("--usd-surface", default="loop", choices=("loop", "baked"),
                         help="loop: the control mesh with subdivisionScheme loop (viewers that refine Loop draw the "
                         "limit surface); baked: the limit surface itself, refined --usd-bake-levels times, for "
                         "viewers without Loop subdivision (Blender, F3D)")  # fmt: skip
    command.add_argument("--usd-bake-levels", type=_refinements, default=2,
                         help="Loop refinements of the baked surface (default 2: 16 triangles per control triangle)")


def _gradient(args) -> int:
    """A quasi-static scene run to its end, then the gradient of its objective at the last equilibrium; a
    walker's by central differences over the worlds of one batch."""
    wp.config.log_level = wp.LOG_WARNING
    module = load_scene(args.scene)
    resolve_device(args.device)
    p = resolve(module.Parameters, getattr(module, "QUICK", {}) if args.quick else None, args.set)

    def report(message):
        print(f"wavewarp grad {module.NAME}: {message}", file=sys.stderr)

    if issubclass(module.Parameters, WalkerParameters) and args.method == "adjoint":
        objective = args.objective or WALKER_OBJECTIVES[0]
        check_adjoint_arguments(args, objective)
        result = walker_adjoint_gradient(module, p, args.wrt, points=args.points, hold_start=args.hold_start,
                                         seed=args.seed, checkpoint_every=args.checkpoint_every, device=args.device,
                                         report=report)  # fmt: skip
        extra = {"method": "adjoint", "start_held": result["start_held"], "checkpoints": result["checkpoints"],
                 "state_bytes": result["state_bytes"]}  # fmt: skip
        if args.points:
            extra["shape_gradient"] = {"points": result["points"], "gradient": result["shape_gradient"].tolist()}
    elif issubclass(module.Parameters, WalkerParameters):
        objective = args.objective or WALKER_OBJECTIVES[0]
        result = walker_gradient(module, p, args.wrt, points=args.points, objective=objective, steps=args.steps,
                                 seed=args.seed, max_worlds=args.max_worlds, device=args.device,
                                 report=report)  # fmt: skip
        extra = {"agreement": result["agreement"], "steps": result["steps"], "period": result["period"]}
        if args.points:
            extra["shape_gradient"] = {"points": result["points"], "gradient": result["shape_gradient"].tolist(),
                                       "agreement": result["shape_agreement"]}  # fmt: skip
            if result["shape_agreement"] > AGREEMENT:
                report(f"d{objective}/dX: the steps {result['steps']} disagree by {result['shape_agreement']:.2g} "
                       "(docs/theory/gradients.md): a shorter run (--set periods=...) or smaller --steps")  # fmt: skip
        for name, agreement in result["agreement"].items():
            if agreement > AGREEMENT:
                report(f"d{objective}/d{name}: the steps {result['steps']} disagree by {agreement:.2g} — past the "
                       "gradient's horizon or at a kink of the walk (docs/theory/gradients.md): a shorter run "
                       "(--set periods=...) or smaller --steps")  # fmt: skip
    else:
        objective = args.objective or OBJECTIVES[0]
        run = module.build(p, device=args.device, seed=args.seed, report=report)
        check_differentiable(run, args.wrt, objective, args.points)
        for _ in range(run.frames):
            run.advance_frame()
        result = scene_gradient(run, args.wrt, objective, args.points)
        extra = {"residual": result["residual"]}
        if args.points:
            extra["shape_gradient"] = {"points": result["points"], "gradient": result["shape_gradient"].tolist()}
    if args.json:
        print(json.dumps({"scene": module.NAME, "objective_name": objective, "objective": result["objective"],
                          "gradient": result["gradient"], **extra}))  # fmt: skip
    else:
        print(f"{objective} = {result['objective']:.10g}")
        for name, value in result["gradient"].items():
            agreement = f"  (steps agree to {extra['agreement'][name]:.2g})" if "agreement" in extra else ""
            print(f"d {objective} / d {name} = {value:.10g}{agreement}")
        if "shape_gradient" in extra:
            agreement = extra["shape_gradient"].get("agreement")
            print(f"d {objective} / d X (per unit length" + (f"; steps agree to {agreement:.2g}" if agreement is not None
                                                              else "") + "):")  # fmt: skip
            for point, row in zip(result["points"], result["shape_gradient"]):
                print(f"  point {point}: {row[0]:+.6g} {row[1]:+.6g} {row[2]:+.6g}")
    return 0


def check_adjoint_arguments(args, objective: str) -> None:
    """Refuse, naming the fix, what --method adjoint does not take."""
    if objective != WALKER_OBJECTIVES[0] or args.max_worlds is not None:
        raise WalkerGradientError("--method adjoint takes the distance objective (no --max-worlds, --objective "
                                  "speed): --method differences for those")  # fmt: skip


def _control_points(text: str):
    if text == "all":
        return text
    try:
        return [int(point) for point in text.split(",") if point]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: control point indices separated by commas, or all") from None


def _relative_steps(text: str) -> tuple:
    try:
        return tuple(float(step) for step in text.split(",") if step)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: relative steps separated by commas, e.g. 1e-4,1e-5") from None


def parser(scene_help: str | None = None) -> argparse.ArgumentParser:
    main_parser = argparse.ArgumentParser(prog="wavewarp", description="Chemical waves on active elastic shells.")
    main_parser.add_argument("--version", action="version", version=f"wavewarp {__version__}")
    commands = main_parser.add_subparsers(dest="command", required=True)
    commands.add_parser("list", help="scene names, one line each").set_defaults(run=_list)
    run = commands.add_parser("run", help="run a scene: USD animation and HDF5 trajectory",
                              epilog=scene_help or "wavewarp run SCENE --help lists SCENE's parameters",
                              formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    run.add_argument("scene", help="a scene name (wavewarp list) or the path of a scene script")
    run.add_argument("--out", default=None, help="USD file (default SCENE.usda)")
    run.add_argument("--h5", default=None, help="HDF5 trajectory to write, frame by frame (or, with --resume, to continue); "
                     "default OUT_trajectory.h5 beside the USD file")
    run.add_argument("--device", default=None, help="cpu, cuda, cuda:N (default: CUDA when present)")
    run.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help="override a scene parameter")
    run.add_argument("--parameters", dest="help_parameters", action="store_true",
                     help="list the scene's parameters with their defaults and meaning, and exit")  # fmt: skip
    _usd_arguments(run)
    run.add_argument("--xdmf", default=None, help="also write frames for ParaView (FILE.xdmf + FILE.h5)")
    run.add_argument("--mesh", default=None, help="any closed triangle mesh file in place of the scene's surface")
    run.add_argument("--quick", action="store_true", help="a reduced run for smoke tests (under a minute on a CPU)")
    run.add_argument("--seed", type=int, default=None,
                     help="seed of the scene's random perturbations (default 0; with --resume, the stored run's)")
    run.add_argument("--resume", action="store_true", help="continue the run stored in --h5 (refused where the "
                     "file holds another run; a finished run's file is left as it is)")
    run.add_argument("--overwrite", action="store_true",
                     help="replace output files that exist (without it, a run refuses to)")
    run.add_argument("--json", action="store_true", help="print one JSON object with the results")
    _deterministic_argument(run)
    run.set_defaults(run=scene_run)
    grid = commands.add_parser("sweep", help="run a scene over a grid of parameter values and seeds (Dask)")
    grid.add_argument("scene", help="a scene name (wavewarp list) or the path of a scene script")
    grid.add_argument("--grid", action="append", default=[], metavar="NAME=V1,V2,...",
                      help="a swept parameter and its values (repeat for a grid)")  # fmt: skip
    grid.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help="a parameter fixed for all points")
    grid.add_argument("--seeds", type=int, default=1, help="K seeds at every grid point: 0 … K-1, or from --first-seed (default 1)")
    grid.add_argument("--first-seed", type=int, default=0, metavar="N",
                      help="start the seeds at N (N … N+K-1): more seeds for an ensemble, in a folder of their own")  # fmt: skip
    grid.add_argument("--batch", type=int, default=1,
                      help="points per task: the worlds of one batched run for scenes that have them (the walkers, buckling, "
                      "buckling-modes), "
                      "else run one after another by a worker")  # fmt: skip
    grid.add_argument("--out", required=True, help="folder of the results (DIR/points/*.json, table.csv, chart.png)")
    grid.add_argument("--device", default=None, choices=("cpu", "cuda"),
                      help="cpu, or cuda (one worker per GPU); default: CUDA when present")  # fmt: skip
    grid.add_argument("--workers", type=int, default=None, help="CPU workers of the local cluster (default: one per core)")
    grid.add_argument("--scheduler", default=None, metavar="ADDRESS",
                      help="an existing Dask scheduler (tcp://host:8786) instead of a local cluster")  # fmt: skip
    grid.add_argument("--quick", action="store_true", help="the scene's reduced run at every point")
    grid.add_argument("--h5", action="store_true",
                      help="also keep every point's trajectory (DIR/points/*.h5), frame by frame: a batch killed "
                      "part-way goes on from its last stored frame when the sweep is run again")  # fmt: skip
    grid.add_argument("--measure", default=None, help="the measurement the chart shows (default: the first that varies)")
    grid.add_argument("--json", action="store_true",
                      help='print one JSON object: {"computed", "skipped", "failed"} (counts) and "failures"')
    _deterministic_argument(grid)
    grid.set_defaults(run=_sweep)
    grad = commands.add_parser("grad", help="gradient of a scene's objective with respect to shell parameters: a "
                               "quasi-static scene's at its last equilibrium, a walker's walk by central differences "
                               "over one batch (docs/theory/gradients.md)")  # fmt: skip
    grad.add_argument("scene", help="a quasi-static scene (oocytes, wave guides, buckling) with --set sensitive=false, "
                      "or a walker")  # fmt: skip
    grad.add_argument("--wrt", default=[], type=lambda text: [name for name in text.split(",") if name],
                      metavar="NAME[,NAME...]", help=f"parameters: quasi-static {', '.join(PARAMETERS)}; walkers "
                      f"{', '.join(WALKER_PARAMETERS)}")  # fmt: skip
    grad.add_argument("--points", default=(), type=_control_points, metavar="I[,I...]|all",
                      help="the rest shape's control points (vertex indices of the scene's mesh, or all) "
                      "whose coordinates the gradient dJ/dX is taken over, per unit length")  # fmt: skip
    grad.add_argument("--max-worlds", type=int, default=None, metavar="N",
                      help="walkers: at most N worlds a batch (device memory; the rest run in further batches given "
                      "the first's steps)")  # fmt: skip
    grad.add_argument("--objective", default=None, help=f"quasi-static: {', '.join(OBJECTIVES)} (default height); walkers: "
                      f"{', '.join(WALKER_OBJECTIVES)} (default: the centre of mass's displacement along the wave, R)")
    grad.add_argument("--steps", type=_relative_steps, default=WALKER_STEPS, metavar="S1,S2",
                      help="walkers: relative steps of the central differences; the largest against the smallest is "
                      f"the reported agreement (default {','.join(f'{s:g}' for s in WALKER_STEPS)})")  # fmt: skip
    grad.add_argument("--method", default="differences", choices=("differences", "adjoint"),
                      help="walkers: central differences over one batch (any parameter, the rest shape), or the "
                      f"reverse mode with checkpoints (one pass for every parameter: {', '.join(ADJOINT_PARAMETERS)}, "
                      "and the rest shape's control points; the overdamped walkers, the "
                      "sensitive or the insensitive wave)")  # fmt: skip
    grad.add_argument("--hold-start", action="store_true",
                      help="--method adjoint: the walk's derivative from its settled start held (needed for all but "
                      "AC and AI, which the settling does not see)")  # fmt: skip
    grad.add_argument("--checkpoint-every", type=int, default=None, metavar="K",
                      help="--method adjoint: chemistry steps between checkpoints (default √N)")
    grad.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help="override a scene parameter")
    grad.add_argument("--device", default=None, help="cpu, cuda, cuda:N (default: CUDA when present)")
    grad.add_argument("--quick", action="store_true", help="the scene's reduced run")
    grad.add_argument("--seed", type=int, default=0, help="seed of the scene's random perturbations")
    grad.add_argument("--json", action="store_true", help="print one JSON object: objective, gradient {name: value}")
    grad.set_defaults(run=_gradient)
    cluster = commands.add_parser("cluster", help="keep a local Dask cluster running for sweeps (--scheduler ADDRESS)")
    cluster.add_argument("--device", default=None, choices=("cpu", "cuda"),
                         help="cpu, or cuda (one worker per GPU); default: CUDA when present")  # fmt: skip
    cluster.add_argument("--workers", type=int, default=None, help="CPU workers (default: one per core)")
    cluster.add_argument("--port", type=_port, default=8786,
                         help="the scheduler's port (default 8786; 0: any free one)")
    cluster.set_defaults(run=_cluster)
    ahead = commands.add_parser("precompile", help="compile the CUDA kernels into Warp's kernel cache ahead of time "
                                "(no GPU needed): GPU machines and sweep workers given the cache load them instead")  # fmt: skip
    ahead.add_argument("--arch", type=int, nargs="+", default=[90],
                       help="CUDA compute capabilities × 10 (default 90: H100, H200; 80: A100)")  # fmt: skip
    ahead.add_argument("--cache", default=None, help="the kernel cache folder (default: WARP_CACHE_PATH or Warp's own)")
    ahead.set_defaults(run=_precompile)
    draw = commands.add_parser("render", help="draw a mesh's Loop limit surface to USD, coloured by mean curvature")
    draw.add_argument("--mesh", default="icosphere", help="icosphere, cube, prism or a mesh file (default icosphere)")
    draw.add_argument("--level", type=int, default=3, help="icosphere level, or cube/prism divisions / 2 (default 3)")
    draw.add_argument("--size", type=float, default=1.0, help="sphere radius or box edge (default 1)")
    draw.add_argument("--rule", default="3", help="quadrature rule: 3, 6, 7, 12 or a composite such as 3x16")
    draw.add_argument("--out", default="surface.usda", help="USD file to write (default surface.usda)")
    draw.add_argument("--device", default=None, help="cpu, cuda, cuda:N (default: CUDA when present)")
    draw.add_argument("--dtype", default="float32", choices=["float32", "float64"])
    _usd_arguments(draw)
    draw.add_argument("--json", action="store_true", help="print one JSON object with the results")
    draw.set_defaults(run=_render)
    bench = commands.add_parser("bench", help="a benchmark: wavewarp bench NAME [--quick] [--device D] [--out DIR] ...")
    bench.add_argument("name", help=f"one of: {', '.join(BENCHMARKS)}")
    bench.add_argument("options", nargs=argparse.REMAINDER, help="the benchmark's own options (wavewarp bench NAME -h)")
    bench.set_defaults(run=_bench)
    return main_parser


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parser(scene_epilog(argv)).parse_args(argv)
    main_thread = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, terminate) if main_thread and args.command != "cluster" else None
    try:
        return args.run(args, argv) if args.run is scene_run else args.run(args)
    except (ValueError, OSError) as error:
        print(f"wavewarp {args.command}: {error}", file=sys.stderr)
        return 2
    except (BlowUpError, RelaxationError) as error:  # a solver failed before the first frame
        print(f"wavewarp {args.command}: {error}", file=sys.stderr)
        return 1
    except KeyboardInterrupt as error:  # Ctrl-C or SIGTERM outside a run's frames: nothing was written
        code = interrupt_signal(error)
        print(f"wavewarp {args.command}: stopped by {signal.Signals(code).name}", file=sys.stderr)
        return 128 + code
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


if __name__ == "__main__":
    sys.exit(main())
