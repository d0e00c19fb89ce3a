"""The driver: runs any scene's run frame by frame into its writers.

    run = module.build(p, mesh=None, device="cpu", seed=0, report=print)
    outcome = simulate(run, [UsdAnimation(...), TrajectoryWriter(...)], progress=True)

A run (wavewarp/runs.py) advances by frames; every writer (USD, HDF5, XDMF) takes each frame with
`add_frame(time, frame)` and is a context manager that keeps its file consistent: written
atomically, with the frames so far kept after Ctrl-C or a solver's failure. A failure of the run
(a blow-up, a relaxation that cannot converge, a time step past its bound) ends the loop with the
frames before it kept and the reason in `Outcome.failure`; so does a frame the disk cannot take (a
full disk: the frames before it stay in the files, and the run can be resumed once there is room).
Resuming replays the stored frames into the run's figures and measurements (and into the writers that
do not hold them) and restores the run's state from the last one.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from dataclasses import dataclass, field

from tqdm import tqdm

from .relax import RelaxationError
from .waves import BlowUpError, TimeStepError

FAILURES = (BlowUpError, RelaxationError, TimeStepError)


@dataclass
class Outcome:
    """What a run ended with: the frames written, the measurements, the figures' paths, and why it stopped
    early (`failure`, the solver's message) or whether it was interrupted."""

    frames: int = 0
    measurements: dict = field(default_factory=dict)
    figures: list = field(default_factory=list)
    failure: str | None = None
    interrupted: bool = False
    signal: int = signal.SIGINT  # the signal that interrupted the run (its exit code: 128 + it)


class Terminated(KeyboardInterrupt):
    """SIGTERM (or another stopping signal), raised where the interpreter was: stops a run as Ctrl-C does."""

    def __init__(self, signum: int = signal.SIGTERM):
        super().__init__(f"stopped by signal {signum}")
        self.signum = int(signum)


def terminate(signum, frame):
    """The SIGTERM handler of a run: raise Terminated."""
    raise Terminated(signum)


def interrupt_signal(error: KeyboardInterrupt) -> int:
    """The signal behind an interrupt: SIGTERM for Terminated, else SIGINT (Ctrl-C)."""
    return error.signum if isinstance(error, Terminated) else int(signal.SIGINT)


def simulate(run, writers, *, progress: bool = False, replay=(), replay_writers=(), figures_stem: str | None = None,
             on_measured=None) -> Outcome:  # fmt: skip
    """Run `run` to its last frame, each frame into every writer of `writers` (context managers, entered
    here). `replay`: stored (time, frame) pairs of a run to continue, written into `replay_writers`
    (those that do not hold them yet) and restored from the last. `progress`: a bar on the terminal.
    `on_measured(measurements)` runs inside the writers' contexts (e.g. to store them in the HDF5
    file). With `figures_stem` the run's figures of the frames kept are written as STEM_NAME.png.
    SIGTERM stops the run as Ctrl-C does, keeping the frames so far (`Outcome.signal` says which)."""
    outcome = Outcome()
    main = threading.current_thread() is threading.main_thread()  # (a sweep's worker runs it in a thread)
    previous = signal.signal(signal.SIGTERM, terminate) if main else None
    bar = tqdm(total=run.frames, desc=getattr(run, "name", "run"), unit="frame", disable=not progress, leave=False)
    unwritten = False
    try:
        with contextlib.ExitStack() as stack:
            for writer in writers:
                stack.enter_context(writer)
            if replay:
                for time, frame in replay:
                    for writer in replay_writers:
                        writer.add_frame(time, frame)
                    run.record(time, frame, stored=True)
                run.restore({**replay[-1][1], "time": replay[-1][0]})
                done = outcome.frames = len(replay) - 1
            else:
                _write(run, writers, run.frame())
                done = 0
            outcome.frames += 1
            bar.update(done)
            while done < run.frames:
                try:
                    run.advance_frame()
                except FAILURES as error:  # the frames so far are complete: keep them
                    outcome.failure = str(error)
                    break
                try:
                    _write(run, writers, run.frame())
                except OSError as error:  # a full disk: the files keep the frames before it
                    unwritten = True
                    outcome.failure = (f"writing frame {outcome.frames} failed ({error}); free space and continue "
                                       "with --resume")
                    break
                done += 1
                outcome.frames += 1
                bar.update(1)
                bar.set_postfix(t=f"{run.time:.4g}")
            outcome.measurements = run.measurements()
            if on_measured is not None and not unwritten:  # (a file short of a frame: a resume measures it)
                on_measured(outcome.measurements)
    except KeyboardInterrupt as error:
        outcome.interrupted, outcome.signal = True, interrupt_signal(error)
        outcome.measurements = run.measurements()
    finally:
        bar.close()
        if main and previous is not None:
            signal.signal(signal.SIGTERM, previous)
    if figures_stem is not None and outcome.frames > 1:  # the figures of the frames kept, also after a stop
        outcome.figures = run.figures(figures_stem)
    return outcome


def _write(run, writers, frame: dict) -> None:
    time = run.time
    for writer in writers:
        writer.add_frame(time, frame)
    run.record(time, frame)

