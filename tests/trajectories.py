"""What the tests of runs, restarts and outputs share: the command line in-process, one-line refusals, a file's
state, a killed run's trajectory, trajectories compared bit for bit, and a scene that waits to be told."""

import hashlib
import json
import os
import shutil
import textwrap

import h5py
import numpy as np

from wavewarp.cli import main


def run_cli(capsys, *args):
    """`wavewarp run ARGS...` in this process: (exit code, stdout, stderr)."""
    code = main(["run", *args])
    out, err = capsys.readouterr()
    return code, out, err


def assert_refused(code, err, *phrases):
    """Exit 2 with one line on stderr, no traceback, that says each of `phrases`."""
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err, err
    assert all(phrase in err for phrase in phrases), err


def file_state(path) -> tuple:
    """The file's bytes (digest) and modification time: what a rewrite would change."""
    return hashlib.sha256(open(path, "rb").read()).hexdigest(), os.stat(path).st_mtime_ns


def killed_copy(full, part, keep: int) -> None:
    """`part`: `full` as a run killed after its first `keep` frames would have left it (no measurements yet)."""
    shutil.copyfile(full, part)
    with h5py.File(part, "r+") as f:
        for name in f["frames"]:
            f["frames"][name].resize((keep, *f["frames"][name].shape[1:]))
        f["frames"].attrs["complete"] = keep
        measured = json.loads(f.attrs["measurements"])
        for name in ["measurements", *measured]:
            if name in f.attrs:
                del f.attrs[name]


def assert_same_trajectory(expected, actual, unlike=("resumed_by",)) -> None:
    """Every dataset equal bit for bit, and every root attribute but those named `unlike` (by default the
    resume's own record, `resumed_by`)."""
    with h5py.File(expected, "r") as a, h5py.File(actual, "r") as b:
        names = []
        a.visit(lambda name: names.append(name) if isinstance(a[name], h5py.Dataset) else None)
        assert names and all(name in b for name in names)
        for name in names:
            np.testing.assert_array_equal(b[name][...], a[name][...], err_msg=name)
        assert ({k: str(v) for k, v in b.attrs.items() if k not in unlike} ==
                {k: str(v) for k, v in a.attrs.items() if k not in unlike})


def waiting_scene(folder) -> str:
    """A scene script: cube-waves whose process, after writing its first frame, creates FOLDER/ready.PID and waits
    until the file FOLDER/go exists (a long run, held where a test wants it; after 600 s it gives up, a guard against
    hanging)."""
    path = folder / "waiting_cube_waves.py"
    path.write_text(textwrap.dedent(f"""
        import os, time
        from wavewarp.scenes import cube_waves
        from wavewarp.scenes.cube_waves import NAME, QUICK, Parameters

        def build(p, **options):
            run = cube_waves.build(p, **options)
            advance = run.advance_frame

            def advance_when_told():
                open(os.path.join({str(folder)!r}, f"ready.{{os.getpid()}}"), "w").close()
                start = time.monotonic()
                while not os.path.exists({str(folder / "go")!r}):
                    if time.monotonic() - start > 600:
                        raise SystemExit("nobody said go")
                    time.sleep(0.05)
                advance()

            run.advance_frame = advance_when_told
            return run
    """))
    return str(path)
