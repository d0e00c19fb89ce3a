"""`wavewarp run`: a scene run into its outputs (docs/theory/scenes.md, "Outputs" and "Resume").

Every output is checked before anything is built and locked while it is written (wavewarp/locks.py);
an existing file is replaced only with --overwrite (a resume rebuilds the USD and XDMF files of the run
it continues). A resume continues only the run its trajectory holds (wavewarp/provenance.py), from its
complete frames, and leaves a finished run's file as it is.
"""

from __future__ import annotations

import json
import os
import sys
import time

import warp as wp

from .device import resolve_device, set_deterministic
from .driver import simulate
from .geometry import limit_positions
from .io import check_writable
from .locks import output_locks
from .mesh import load
from .parameters import help_lines, load_scene, resolve, resumed
from .provenance import resume_mismatch, run_provenance
from .sizing import check_output_size
from .trajectory import TrajectoryWriter, read_frames, stored_run
from .usd import UsdAnimation
from .version import __version__
from .xdmf import XdmfWriter


def output_paths(args, module) -> tuple:
    """(USD, HDF5, [XDMF file and its data file]) of the run, each checked writable."""
    out = args.out or f"{module.NAME}.usda"
    h5 = args.h5 or f"{os.path.splitext(out)[0]}_trajectory.h5"
    xdmf = []
    if args.xdmf:
        if not args.xdmf.endswith(".xdmf"):
            raise ValueError(f"XDMF output {args.xdmf!r} must end in .xdmf")
        sidecar = os.path.splitext(args.xdmf)[0] + ".h5"
        if os.path.abspath(sidecar) == os.path.abspath(h5):
            raise ValueError(f"--xdmf {args.xdmf} keeps its data in {sidecar}, the --h5 file: choose another name")
        xdmf = [args.xdmf, sidecar]
    for path in [out, h5, *xdmf]:
        check_writable(path)
    return out, h5, xdmf


def refuse_existing(paths, h5: str) -> None:
    """ValueError naming the first of `paths` that exists: a new run replaces no file without --overwrite."""
    for path in paths:
        if os.path.lexists(path):
            resume = ", --resume continues the run it holds" if path == h5 else ""
            raise ValueError(f"{path!r} exists: --overwrite replaces it{resume}; or write to another file (--out, "
                             "--h5)")


def resume_record(module, h5: str, args) -> dict:
    """The trajectory --resume continues (wavewarp.trajectory.stored_run), refused in one line where it is
    missing, combined with --set, or of another scene, version or seed."""
    if not os.path.isfile(h5):
        raise ValueError(f"--resume continues the trajectory {h5!r}, which does not exist: pass --h5 FILE.h5, the "
                         "trajectory of the run to continue")
    if args.set:
        raise ValueError(f"--set cannot be combined with --resume: the run continues with the parameters stored in "
                         f"{h5}")
    stored = stored_run(h5)
    this = {"scene": module.NAME, "wavewarp_version": __version__}
    mismatch = resume_mismatch(stored, {**this, **({} if args.seed is None else {"seed": args.seed})})
    if mismatch is not None:
        raise ValueError(f"cannot resume {h5!r}: {mismatch}")
    if stored["frames"] == 0:
        raise ValueError(f"cannot resume {h5!r}: it has no frames")
    return stored


def finished(stored: dict, frames: int) -> bool:
    """Whether a trajectory holds its whole run: all its `frames` (the first included) and the measurements."""
    return stored["frames"] >= frames and "measurements" in stored


def report_complete(module, h5: str, stored: dict, as_json: bool) -> int:
    """A finished run's --resume: said, the file untouched."""
    if as_json:
        print(json.dumps({"scene": module.NAME, "frames": stored["frames"], "outputs": [h5], "complete": True,
                          **json.loads(stored["measurements"])}))
    else:
        print(f"{h5} holds the finished run ({stored['frames']} frames): nothing to resume; no file was changed")
    return 0


def scene_run(args, arguments) -> int:
    """`wavewarp run`; `arguments`, the command's words after `wavewarp`, go to the trajectory's provenance."""
    wp.config.log_level = wp.LOG_WARNING
    start = time.perf_counter()
    module = load_scene(args.scene)
    if args.help_parameters:
        print("\n".join(help_lines(module.Parameters)))
        return 0
    resolve_device(args.device)  # an unavailable device is refused before anything is built
    set_deterministic(args.deterministic)
    out, h5_path, xdmf = output_paths(args, module)
    with output_locks([out, h5_path, *xdmf]):
        stored = resume_record(module, h5_path, args) if args.resume else None
        if stored is None:
            p = resolve(module.Parameters, getattr(module, "QUICK", {}) if args.quick else None, args.set)
            if not args.overwrite:
                refuse_existing([out, h5_path, *xdmf], h5_path)
        else:
            p = resumed(module.Parameters, stored["parameters"])
        seed = args.seed if args.seed is not None else int(stored.get("seed", 0)) if stored else 0
        return _run(module, p, args, arguments, seed=seed, stored=stored, paths=(out, h5_path, xdmf), start=start)


def _run(module, p, args, arguments, *, seed: int, stored, paths: tuple, start: float) -> int:
    out, h5_path, xdmf_paths = paths

    def report(message):
        print(f"wavewarp run {module.NAME}: {message}", file=sys.stderr)

    run = module.build(p, mesh=load(args.mesh) if args.mesh else None, device=args.device, seed=seed, report=report)
    if stored is not None and finished(stored, run.frames + 1):
        return report_complete(module, h5_path, stored, args.json)
    usd = UsdAnimation(out, run.mesh.triangles, field_name="concentration", surface=args.usd_surface,
                       bake_levels=args.usd_bake_levels, ground_size=getattr(run, "ground_size", 0.0))
    check_output_size(run.frames + 1, run.series, usd.points_per_frame, os.path.dirname(os.path.abspath(h5_path)))
    provenance = run_provenance(seed=seed, mesh_path=os.path.abspath(args.mesh) if args.mesh else None,
                                frames=run.frames + 1, arguments=arguments)
    h5 = TrajectoryWriter(h5_path, triangles=run.mesh.triangles, rest_positions=run.mesh.vertices, series=run.series,
                          scene=module.NAME, parameters=run.resolved, device=str(run.shell.device),
                          resume=stored is not None, provenance=provenance,
                          attributes={"time_unit": getattr(run, "time_unit", "the scene's time unit")})
    if stored is not None:
        h5.check_resumable()  # another mesh or rest shape: refused before any file is touched
    writers, replay_writers = [usd, h5], [usd]
    if xdmf_paths:
        device = run.operator.device

        def limit_points(x):
            return limit_positions(run.mesh, x, device=device, dtype="float64")

        xdmf = XdmfWriter(xdmf_paths[0], triangles=run.mesh.triangles, rest_points=limit_points(run.mesh.vertices),
                          limit_points=limit_points, field_values=run.operator.field_values)
        writers.append(xdmf)
        replay_writers.append(xdmf)
    replay = read_frames(h5_path) if stored is not None else ()
    outcome = simulate(run, writers, progress=sys.stderr.isatty(), replay=replay, replay_writers=replay_writers,
                       figures_stem=os.path.splitext(out)[0], on_measured=h5.set_measurements)
    outputs = [out, h5_path] + xdmf_paths[:1] + outcome.figures
    summary = {"scene": module.NAME, "device": str(run.shell.device), "steps": run.steps, "frames": outcome.frames,
               "wall_time_s": time.perf_counter() - start, "outputs": outputs, "interrupted": outcome.interrupted,
               "stopped": outcome.failure, **outcome.measurements}
    if args.json:
        print(json.dumps(summary))
    if outcome.failure:
        print(f"wavewarp run {module.NAME}: {outcome.failure}; kept the {outcome.frames} frames before it",
              file=sys.stderr)
        return 1
    if not args.json:
        state = "interrupted; kept" if outcome.interrupted else "wrote"
        print(f"{state} {outcome.frames} frames to {', '.join(outputs)} ({summary['wall_time_s']:.1f} s, "
              f"{run.steps} wave steps)")
    return 128 + outcome.signal if outcome.interrupted else 0
