"""Advisory locks on output files (the `filelock` library): one writer per file at a time.

`output_locks(paths)` holds, for each output, the lock file `.NAME.lock` beside it, taken without waiting:
a second process that would write the same file is refused in one line naming the process that holds
it. The lock file names its holder's process id; it is removed when released (a lock file left by a
killed process holds no lock: the next writer takes it).
"""

from __future__ import annotations

import contextlib
import os

from filelock import FileLock, Timeout


class OutputBusy(ValueError):
    """Another process holds an output's lock."""


def lock_path(path) -> str:
    """The lock file of output `path`: `.NAME.lock` in its folder."""
    directory, name = os.path.split(os.path.abspath(os.fspath(path)))
    return os.path.join(directory, f".{name}.lock")


def _holder(lock_file: str) -> str:
    try:
        with open(lock_file) as f:
            pid = f.read().strip()
    except OSError:
        return "another process"
    return f"process {pid}" if pid.isdigit() else "another process"


@contextlib.contextmanager
def output_lock(path, what: str = "output"):
    """Hold the lock of output `path` for the context; OutputBusy (a ValueError) at once if another process
    holds it."""
    lock_file = lock_path(path)
    lock = FileLock(lock_file, timeout=0)
    try:
        lock.acquire()
    except Timeout:
        raise OutputBusy(f"{what} {os.fspath(path)!r} is being written by {_holder(lock_file)} (lock {lock_file}): "
                         "wait for it to finish, or write to another file") from None
    try:
        with open(lock_file, "w") as f:  # a second handle: the lock is on the file, this only names its holder
            f.write(str(os.getpid()))
        yield
    finally:
        with contextlib.suppress(OSError):
            os.remove(lock_file)  # while held: a process that opened it before sees it unlinked and retries
        lock.release()


@contextlib.contextmanager
def output_locks(paths, what: str = "output"):
    """`output_lock` on every path of `paths` (the same file named twice locked once)."""
    with contextlib.ExitStack() as stack:
        for path in dict.fromkeys(os.path.abspath(os.fspath(p)) for p in paths):
            stack.enter_context(output_lock(path, what))
        yield
