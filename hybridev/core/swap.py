"""Crash-consistent replacement of folders and recovery after a crash (for :mod:`hybridev.core.outputs`).

The promise: at every instant the user's path holds either the complete old
output or the complete new one, whatever kills the process (an exception,
SIGINT, SIGTERM, SIGKILL, a power cut after the file system's journal replay).

How:

* A new output is built under a hidden sibling ``.<name>.<pid>.<random>.tmp``.
* On Linux the finished folder and the old one trade places in **one atomic
  step**, ``renameat2(RENAME_EXCHANGE)`` (:func:`exchange`); the hidden name then
  holds the old folder, which is removed. A new output with no old one is moved
  in by one :func:`os.rename`. There is no instant without the output.
* Where the exchange is not available (another OS, a file system without it, or
  ``HYBRIDEV_NO_EXCHANGE=1``), the old folder is first renamed to
  ``.<name>.<pid>.old`` (the *journal*: its presence records the step), then the
  new one moved in. A signal in between puts the old folder back before the
  process ends; after a SIGKILL in between, the next run (:func:`recover`)
  does.
* :func:`recover` runs before every write of an output: a leftover
  ``.<name>.<pid>...tmp`` or ``.<name>.<pid>.old`` of a process that no longer
  runs is removed, or (an ``.old`` where the output is missing) restored. Each
  action is reported by an :class:`~hybridev.core.errors.RecoveryWarning`.

Fault injection (for the tests): ``HYBRIDEV_FAULT="<step>:<SIGNAL>"`` makes the
process send itself ``SIGNAL`` when it reaches ``step`` (:func:`fault`); the
steps of each writer are listed in :data:`STEPS`.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import errno
import os
import re
import signal
import sys
import warnings
from pathlib import Path

from hybridev.core.cleanup import remove_path
from hybridev.core.errors import RecoveryWarning

__all__ = ["STEPS", "exchange", "fault", "leftover_name", "pid_alive", "recover", "replace_dir"]

STEPS = {
    "dir": ("dir.written", "dir.manifest", "dir.swapped", "dir.old_moved", "dir.done"),
    "file": ("file.written", "file.pending", "file.replaced", "file.done"),
    "merge": ("merge.written", "merge.journal", "merge.moved", "merge.manifest", "merge.done"),
}
"""Fault-injection steps of each writer (``dir.old_moved`` only without the exchange)."""

_RENAME_EXCHANGE = 2
_AT_FDCWD = -100
_LEFTOVER = re.compile(r"^\.(?P<name>.+?)\.(?P<pid>\d+)\.(?:(?P<rand>[^.]+)\.tmp|old|tmp)$")


def fault(step: str) -> None:
    """Send this process the signal named in ``HYBRIDEV_FAULT`` when it names ``step``.

    ``HYBRIDEV_FAULT="dir.swapped:SIGKILL"``; several entries separated by commas.
    Does nothing (one environment lookup) otherwise.
    """
    spec = os.environ.get("HYBRIDEV_FAULT")
    if not spec:
        return
    for item in spec.split(","):
        name, _, sig = item.strip().partition(":")
        if name == step:
            os.kill(os.getpid(), getattr(signal, sig or "SIGKILL"))


def _renameat2():
    if not sys.platform.startswith("linux") or os.environ.get("HYBRIDEV_NO_EXCHANGE"):
        return None
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or None, use_errno=True)
        f = libc.renameat2
    except (OSError, AttributeError):
        return None
    f.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    f.restype = ctypes.c_int
    return f


def exchange(a: str | os.PathLike, b: str | os.PathLike) -> bool:
    """Swap two existing paths atomically; False when the OS or file system cannot.

    Raises :class:`OSError` for any other failure (permission, missing path).
    """
    f = _renameat2()
    if f is None:
        return False
    if f(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.ENOSYS, errno.EINVAL, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EPERM):
        return False
    raise OSError(err, os.strerror(err), os.fspath(a), None, os.fspath(b))


def leftover_name(target: Path, what: str) -> Path:
    """The hidden sibling ``.<name>.<pid>.old`` (``what="old"``) of ``target``."""
    return target.with_name(f".{target.name}.{os.getpid()}.{what}")


def pid_alive(pid: int) -> bool:
    """Whether a process ``pid`` runs (ours counts as running)."""
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, OSError):
        return True  # another user's process, or unknown: leave its files alone
    return True


def recover(target: str | os.PathLike, *, names: tuple[str, ...] = ()) -> list[str]:
    """Clean or restore what a crashed earlier run left beside ``target``; return the notes.

    ``names``: further entries of the same folder whose leftovers are cleaned
    (e.g. the register of file outputs). Leftovers of running processes are
    left alone. Each action is also reported as a :class:`RecoveryWarning`.
    """
    target = Path(target)
    parent = target.parent
    wanted = {target.name, *names}
    notes: list[str] = []
    try:
        entries = sorted(os.listdir(parent))
    except OSError:
        return notes
    olds, tmps = [], []
    for entry in entries:
        m = _LEFTOVER.match(entry)
        if m is None or m.group("name") not in wanted or pid_alive(int(m.group("pid"))):
            continue
        (olds if entry.endswith(".old") else tmps).append((m.group("name"), parent / entry))
    for name, p in olds:
        dest = parent / name
        try:
            if not os.path.lexists(dest):
                os.rename(p, dest)
                notes.append(f"restored {str(dest)!r} from {p.name!r}, left by an interrupted "
                             "earlier run (its new output was incomplete)")
                continue
        except OSError:
            pass
        remove_path(p)
        notes.append(f"removed {p.name!r}, the previous version of {str(dest)!r} left by an "
                     "interrupted earlier run")
    for name, p in tmps:
        remove_path(p)
        notes.append(f"removed {p.name!r}, a temporary output left by an interrupted earlier "
                     f"run (beside {str(parent / name)!r})")
    for note in notes:
        warnings.warn(note, RecoveryWarning, stacklevel=3)
    return notes


def replace_dir(tmp: Path, target: Path, state: dict) -> None:
    """Move the complete folder ``tmp`` to ``target``, replacing any old one atomically.

    ``state["old"]`` is set to the path that holds the old folder afterwards
    (removed by the caller's clean-up); ``state`` is updated *before* each step
    so that a signal handler always knows what to undo.
    """
    if not os.path.lexists(target):
        state["old"] = None
        os.rename(tmp, target)  # fails (ENOTEMPTY/EEXIST) if another run made it meanwhile
        fault("dir.swapped")
        return
    state["old"] = tmp  # after the exchange ``tmp`` holds the old folder
    if exchange(tmp, target):
        fault("dir.swapped")
        return
    old = leftover_name(target, "old")  # the journal: present = the old folder moved here
    remove_path(old)
    state["old"] = old
    os.rename(target, old)
    fault("dir.old_moved")
    os.rename(tmp, target)
    fault("dir.swapped")


def undo_dir(tmp: Path, target: Path, state: dict) -> None:
    """Clean-up of an interrupted :func:`replace_dir` (idempotent): put the old back, drop tmp."""
    old = state.get("old")
    if old is not None and old != tmp and not os.path.lexists(target) and os.path.lexists(old):
        with contextlib.suppress(OSError):
            os.rename(old, target)  # interrupted between the two renames: the old comes back
    remove_path(tmp)
    if old is not None and old != tmp and os.path.lexists(target):
        remove_path(old)
