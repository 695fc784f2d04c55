"""One process at a time: an operating-system lock on a file.

Two uses: a training run holds its run folder's lock while it writes there (a second run into
the same folder is refused), and the shared caches (the course's dataset, the cache of trained
models) are filled under a lock that others wait for, so that two notebooks, or two test
workers, asking for the same model or data at once train or write it once and then share it.
The operating system releases a lock when its process dies, so a killed run never leaves a
folder locked.
"""

from __future__ import annotations

import contextlib
import os
import time
from pathlib import Path

#: Seconds between two tries while waiting for another process's lock.
POLL_S = 0.5


class LockedError(OSError):
    """Another process holds the lock (and the caller chose not to wait); ``holder`` names it:
    ``"process 1234"``, or ``"another process"`` if it has not yet written its number."""

    def __init__(self, path: Path, holder: str):
        super().__init__(f"{holder} holds {path}")
        self.holder = holder


def _try_lock(stream) -> bool:
    """Take an exclusive lock on an open file if free; True if taken."""
    try:
        if os.name == "nt":
            import msvcrt

            msvcrt.locking(stream.fileno(), msvcrt.LK_NBLCK, 1)
        else:
            import fcntl

            fcntl.flock(stream.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        return False
    return True


@contextlib.contextmanager
def exclusive(path: str | Path, *, wait_for: str | None = None, remove: bool = False):
    """Hold the lock on ``path`` (created if missing; it names the holding process) for the
    ``with`` block.

    Args:
        path: the lock file; its folder must exist.
        wait_for: None to raise at once if another process holds the lock; else wait for it,
            having printed once ``"Waiting for process PID, which is {wait_for}"``.
        remove: delete the file on release (only where nobody waits for it: a waiter could
            otherwise lock the deleted file while a newcomer locks a new one).
    Raises:
        LockedError: naming the holding process, when ``wait_for`` is None and the lock is held.
    """
    path = Path(path)
    stream = open(path, "a+")  # noqa: SIM115 - held open for the whole block
    try:
        announced = False
        while not _try_lock(stream):
            stream.seek(0)
            number = stream.read().strip()  # empty for a moment after the holder has locked
            holder = f"process {number}" if number else "another process"
            if wait_for is None:
                raise LockedError(path, holder)
            if not announced:
                print(f"Waiting for {holder}, which is {wait_for}", flush=True)
                announced = True
            time.sleep(POLL_S)
        stream.seek(0)
        stream.truncate()
        stream.write(str(os.getpid()))
        stream.flush()
        try:
            yield
        finally:
            if remove:
                path.unlink(missing_ok=True)
    finally:
        stream.close()  # closing releases the lock
