"""One process at a time in a run folder: `run_lock(workdir)` holds `workdir/.jaxmotion.lock`.

    with run_lock("runs/dlow_h36m"):       # RunFolderError naming the folder and the holder's pid if held
        experiment.train(...)

The lock is an `fcntl.flock` on the file, which the kernel drops when its holder exits however it
exits (a kill included), so a lock left by a dead process is free and taken over; the file records
the holder's process id and host, for the message a second process gets.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import socket
from collections.abc import Iterator
from pathlib import Path

from jaxmotion.errors import RunFolderError

LOCK_FILE = ".jaxmotion.lock"


@contextlib.contextmanager
def run_lock(workdir: str | os.PathLike, what: str = "jaxmotion") -> Iterator[Path]:
    """Holds `workdir`'s lock (the folder created) for the block; yields the lock file's path.

    Raises `RunFolderError` naming the folder when another live process holds it (with its process id)
    or when the folder cannot be written.
    """
    workdir = Path(workdir).absolute()
    path = workdir / LOCK_FILE
    try:
        workdir.mkdir(parents=True, exist_ok=True)
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    except OSError as e:
        raise RunFolderError(workdir, f"cannot write to the run folder ({type(e).__name__}: {e.strerror or e})") from None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 256, 0).decode(errors="replace").split()
            pid = holder[0] if holder else "unknown"
            host = f" on {holder[1]}" if len(holder) > 1 else ""
            raise RunFolderError(
                workdir, f"in use by another jaxmotion process (pid {pid}{host}, lock file {LOCK_FILE}); "
                "wait for it to finish, or choose another --workdir"
            ) from None
        try:  # a folder made read-only after the lock file was written: found now, not after the work
            os.ftruncate(fd, 0)
            os.pwrite(fd, f"{os.getpid()} {socket.gethostname()} {what}\n".encode(), 0)
            probe = workdir / f".jaxmotion.write-test.{os.getpid()}"
            probe.touch()
            probe.unlink()
        except OSError as e:
            raise RunFolderError(workdir, f"cannot write to the run folder ({type(e).__name__}: {e.strerror or e})") from None
        try:
            yield path
        finally:
            os.ftruncate(fd, 0)  # released: no pid left that a reader could mistake for a holder
    finally:
        os.close(fd)
