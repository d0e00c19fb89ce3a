"""Output files that are never half-written: temporary siblings named by their process, renamed into
place when complete; the temporaries of a killed process are removed by the next writer."""

from __future__ import annotations

import contextlib
import glob
import json
import os
import re
import tempfile


def check_writable(path) -> None:
    """Raise ValueError naming `path` if it could not be written (its folder is missing, read-only or
    not a place for files, as /proc): a real file is created beside it and removed."""
    shown = os.fspath(path)
    path = os.path.abspath(shown)
    directory = os.path.dirname(path)
    if os.path.isdir(path):
        raise ValueError(f"cannot write {shown!r}: it is a folder; name a file")
    if not os.path.isdir(directory):
        raise ValueError(f"cannot write {shown!r}: folder {directory!r} does not exist")
    try:
        handle, probe = tempfile.mkstemp(prefix=".wavewarp-probe.", dir=directory)
        os.close(handle)
        os.remove(probe)
    except OSError as error:
        raise ValueError(f"cannot write {shown!r}: folder {directory!r} does not take new files "
                         f"({error.strerror or error})") from None  # fmt: skip


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    return True


def temporary_prefix(path) -> str:
    """The prefix of `path`'s temporary siblings (files and folders): `.NAME.PID.`."""
    directory, name = os.path.split(os.path.abspath(os.fspath(path)))
    return os.path.join(directory, f".{name}.{os.getpid()}.")


def remove_stale_temporaries(path) -> list:
    """Remove the temporary siblings of `path` left by processes that no longer run (a kill -9, a power
    cut); returns what was removed."""
    directory, name = os.path.split(os.path.abspath(os.fspath(path)))
    pattern = re.compile(rf"^\.{re.escape(name)}\.(\d+)\.")
    removed = []
    for candidate in glob.glob(os.path.join(glob.escape(directory), f".{glob.escape(name)}.*")):
        match = pattern.match(os.path.basename(candidate))
        if match is None or _alive(int(match.group(1))):
            continue
        with contextlib.suppress(OSError):
            if os.path.isdir(candidate):
                for inner in os.listdir(candidate):
                    os.remove(os.path.join(candidate, inner))
                os.rmdir(candidate)
            else:
                os.remove(candidate)
            removed.append(candidate)
    return removed


def temporary_file(path) -> str:
    """A new empty temporary sibling of `path` (same extension), after removing stale ones."""
    check_writable(path)
    remove_stale_temporaries(path)
    prefix = temporary_prefix(path)
    handle, tmp = tempfile.mkstemp(prefix=os.path.basename(prefix), suffix=f".tmp{os.path.splitext(os.fspath(path))[1]}",
                                   dir=os.path.dirname(prefix))  # fmt: skip
    os.close(handle)
    return tmp


def move_into_place(tmp, path) -> None:
    """Rename the finished temporary `tmp` to `path`, with the permissions a plain open() would give."""
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600
    os.replace(tmp, os.path.abspath(os.fspath(path)))


@contextlib.contextmanager
def atomic_path(path):
    """Yield a temporary path beside `path` (same extension); on success it replaces `path`.

    On any exception the temporary file is removed and `path` is left untouched.
    """
    tmp = temporary_file(path)
    try:
        yield tmp
        move_into_place(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.remove(tmp)
        raise


def write_json(path, data) -> None:
    """`data` as indented JSON at `path`, atomically."""
    with atomic_path(path) as tmp, open(tmp, "w") as f:
        json.dump(data, f, indent=1)


def write_png(fig, path, dpi: int = 120) -> None:
    """A matplotlib figure as PNG at `path`, atomically; the figure is closed."""
    import matplotlib.pyplot as plt

    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi, format="png")
    plt.close(fig)


def write_result(result: dict, out: str, stem: str, chart) -> str:
    """A benchmark's `result` as OUT/STEM.json and `chart(result, path)` as OUT/STEM.png; returns OUT/STEM."""
    os.makedirs(out, exist_ok=True)
    path = os.path.join(out, stem)
    write_json(path + ".json", result)
    chart(result, path + ".png")
    print(f"wrote {path}.json, {path}.png")
    return path
