"""Atomic file output: write to a temporary sibling, then rename (no half-written files)."""

from __future__ import annotations

import contextlib
import json
import os
import tempfile


def check_writable(path) -> None:
    """Raise ValueError naming the problem if `path` could not be written (its folder is missing or read-only)."""
    path = os.path.abspath(os.fspath(path))
    directory = os.path.dirname(path)
    if not os.path.isdir(directory):
        raise ValueError(f"cannot write {path!r}: folder {directory!r} does not exist")
    if not os.access(directory, os.W_OK):
        raise ValueError(f"cannot write {path!r}: folder {directory!r} is not writable")


@contextlib.contextmanager
def atomic_path(path):
    """Yield a temporary path beside `path` (same extension); on success it replaces `path`.

    On any exception the temporary file is removed and `path` is left untouched.
    """
    check_writable(path)
    path = os.path.abspath(os.fspath(path))
    directory, name = os.path.split(path)
    stem, suffix = os.path.splitext(name)
    handle, tmp = tempfile.mkstemp(prefix=f".{stem}.", suffix=f".tmp{suffix}", dir=directory)
    os.close(handle)
    try:
        yield tmp
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; a plain open() would honour the umask
        os.replace(tmp, path)
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
