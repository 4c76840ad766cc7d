"""One writer per output: an exclusive flock held by the run that writes a folder or file.

The lock is a small file beside the output, ``PARENT/.NAME.aquarom-lock``, holding the PID of the
run that holds it. A run takes it before it looks at the output and keeps it until it ends; a
second run on the same output is refused at once (no waiting) with that PID. The holder removes
the lock file when it releases the lock (the lock is released by the kernel if the process dies,
and the stale file is taken over by the next run). Under MPI only rank 0 takes the lock.

Taking the lock follows the usual pattern for removable lock files: open (create), flock without
blocking, then check that the path still names the locked file (a holder may have removed it in
between); otherwise try again.
"""
from __future__ import annotations

import atexit
import errno
import fcntl
import os
import stat
from dataclasses import dataclass
from pathlib import Path

from aquarom_fenics.errors import InputError

LOCK_SUFFIX = ".aquarom-lock"


@dataclass
class OutputLock:
    """An exclusive lock on one output (``target``), held through the open ``descriptor``."""

    target: Path
    file: Path
    descriptor: int
    in_folder: bool = False       # an flock on the folder itself: no lock file to remove


_held: list[OutputLock] = []


def lock_file_of(target: Path) -> Path:
    """``PARENT/.NAME.aquarom-lock`` of an output folder or file (its real path: a symlink and its
    target share one lock)."""
    target = Path(target).resolve()
    return target.with_name(f".{target.name}{LOCK_SUFFIX}")


def lock_output(target: Path) -> OutputLock:
    """Take the exclusive lock of ``target`` for the rest of this run (its parent folder must exist).

    Raises InputError naming the holder's PID when another process holds it.
    """
    target = Path(target)
    path = lock_file_of(target)
    for held in _held:
        if held.file == path:
            return held
    while True:
        try:
            descriptor = _open_lock_file(path)
        except OSError as error:
            if Path(target).is_dir() and error.errno in (errno.EACCES, errno.EPERM, errno.EROFS):
                return _lock_folder_itself(Path(target))
            if error.errno == errno.ELOOP:
                raise InputError(f"output {target}: its lock file {path} is a symbolic link, never followed; "
                                 "remove it (it is not the toolkit's) or choose another --out") from None
            raise InputError(f"output {target}: cannot create its lock file {path} ({error.strerror}); "
                             "choose a writable location for --out") from None
        if descriptor is None:
            continue                  # created and removed by another run meanwhile: try again
        try:
            fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = _holder(descriptor)
            os.close(descriptor)
            raise InputError(f"output {target} is being written by another aquarom run ({holder}); "
                             "wait for it to end or choose another --out") from None
        if _names_the_same_file(path, descriptor):
            break
        os.close(descriptor)          # the previous holder removed it meanwhile: take the new one
    os.ftruncate(descriptor, 0)
    os.write(descriptor, f"{os.getpid()}\n".encode())
    lock = OutputLock(target, path, descriptor)
    _held.append(lock)
    return lock


def _open_lock_file(path: Path) -> int | None:
    """A descriptor of the lock file, never through a link: created new (O_CREAT | O_EXCL), or the
    existing one opened with O_NOFOLLOW, which must be a regular file with one link (a hard link
    to another file, a FIFO or a device is refused: the lock's PID would be written into it).
    None when the file vanished between the two opens."""
    flags = os.O_RDWR | os.O_CLOEXEC | os.O_NOFOLLOW | os.O_NONBLOCK
    try:
        return os.open(path, flags | os.O_CREAT | os.O_EXCL, 0o644)
    except FileExistsError:
        pass
    try:
        descriptor = os.open(path, flags)
    except FileNotFoundError:
        return None
    details = os.fstat(descriptor)
    if not stat.S_ISREG(details.st_mode) or details.st_nlink != 1:
        os.close(descriptor)
        what = "not a regular file" if not stat.S_ISREG(details.st_mode) else "a hard link to another file"
        raise InputError(f"lock file {path} is {what}; it is not the toolkit's: remove it or choose another --out")
    return descriptor


def _lock_folder_itself(target: Path) -> OutputLock:
    """The lock of an existing folder whose parent takes no files (``--out .`` in a folder of a
    read-only parent): an flock on the folder itself, its holder found in /proc/locks."""
    descriptor = os.open(target, os.O_RDONLY | os.O_CLOEXEC)
    try:
        fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        holder = _holder_in_proc_locks(os.fstat(descriptor).st_ino)
        os.close(descriptor)
        raise InputError(f"output {target} is being written by another aquarom run ({holder}); "
                         "wait for it to end or choose another --out") from None
    lock = OutputLock(target, lock_file_of(target), descriptor, in_folder=True)
    _held.append(lock)
    return lock


def _holder_in_proc_locks(inode: int) -> str:
    """'PID n' of the process holding an flock on the file with this inode (Linux /proc/locks)."""
    try:
        lines = Path("/proc/locks").read_text().splitlines()
    except OSError:
        return "PID unknown"
    for line in lines:
        fields = line.split()
        if len(fields) > 5 and fields[1] == "FLOCK" and fields[5].rsplit(":", 1)[-1] == str(inode):
            return f"PID {fields[4]}"
    return "PID unknown"


def holds_lock(target: Path) -> bool:
    """This process holds the lock of ``target``."""
    path = lock_file_of(target)
    return any(held.file == path for held in _held)


def is_locked_by_another(target: Path) -> str | None:
    """``"PID n"`` when another process writes ``target`` now, else None (a reader's test: the
    lock is tried and released again at once)."""
    path = lock_file_of(target)
    if holds_lock(target) or not path.exists():
        return None
    try:
        descriptor = os.open(path, os.O_RDONLY | os.O_CLOEXEC | os.O_NOFOLLOW | os.O_NONBLOCK)
    except OSError:
        return None
    try:
        fcntl.flock(descriptor, fcntl.LOCK_SH | fcntl.LOCK_NB)
        return None
    except BlockingIOError:
        return _holder(descriptor)
    finally:
        os.close(descriptor)


def release_output_locks(folder: Path | None = None) -> None:
    """Remove the lock files this process holds and release the locks (at the end of a command);
    with ``folder``, only those whose lock file is in it (a refused run removing its folders)."""
    chosen = [lock for lock in _held if folder is None or lock.file.parent == Path(folder).resolve()]
    for lock in chosen:
        _held.remove(lock)
        try:
            if not lock.in_folder and _names_the_same_file(lock.file, lock.descriptor):
                lock.file.unlink()
        except OSError:
            pass
        os.close(lock.descriptor)


def _names_the_same_file(path: Path, descriptor: int) -> bool:
    try:
        named, opened = os.stat(path), os.fstat(descriptor)
    except OSError:
        return False
    return (named.st_dev, named.st_ino) == (opened.st_dev, opened.st_ino)


def _holder(descriptor: int) -> str:
    """'PID n' from the lock file's content ('PID unknown' while the holder is writing it)."""
    try:
        text = os.pread(descriptor, 32, 0).decode(errors="replace").strip()
    except OSError:
        text = ""
    return f"PID {text}" if text.isdigit() else "PID unknown"


atexit.register(release_output_locks)
