"""Temporary paths removed on error and on SIGINT/SIGTERM (used by :mod:`hybridev.core.outputs`).

:func:`guard` registers a clean-up action for the duration of a ``with``
block. While any is registered, SIGTERM and SIGINT handlers (main thread only)
run every pending action, restore the previous handler and re-deliver the
signal, so the process ends as it would have, minus the temporary files.
"""

from __future__ import annotations

import contextlib
import itertools
import os
import shutil
import signal
import threading
from collections.abc import Callable, Iterator
from pathlib import Path

__all__ = ["guard", "remove_path"]

_PENDING: dict[int, Callable[[], None]] = {}
_PREVIOUS: dict[int, object] = {}
_LOCK = threading.RLock()
_COUNTER = itertools.count()
_SIGNALS = tuple(s for s in (getattr(signal, "SIGTERM", None), getattr(signal, "SIGINT", None))
                 if s is not None)


def _cleanup_all() -> None:
    with _LOCK:
        actions = list(_PENDING.values())[::-1]
        _PENDING.clear()
    for act in actions:
        with contextlib.suppress(Exception):
            act()


_INTERRUPTED: list[int] = []
"""SIGINTs whose KeyboardInterrupt is on its way: raised again by :func:`guard` if lost."""


def _on_signal(signum, frame) -> None:
    _cleanup_all()
    prev = _PREVIOUS.pop(signum, signal.SIG_DFL)
    with contextlib.suppress(ValueError, TypeError):
        signal.signal(signum, prev)
    if prev is signal.default_int_handler:
        # Python runs a handler at the next bytecode of the main thread, which may be
        # inside a finaliser (__del__): there the KeyboardInterrupt is printed as
        # "Exception ignored" and lost, and the program ran on (a saving loop never
        # ended). Remember it: the enclosing guard raises it again when it ends.
        _INTERRUPTED.append(signum)
    if callable(prev):
        prev(signum, frame)  # e.g. KeyboardInterrupt for SIGINT
    else:
        os.kill(os.getpid(), signum)  # the default action, with the usual exit status


def _install() -> None:
    if threading.current_thread() is not threading.main_thread():
        return
    for s in _SIGNALS:
        if s in _PREVIOUS:
            continue
        cur = signal.getsignal(s)
        if cur in (signal.SIG_IGN, None) or cur is _on_signal:
            continue
        with contextlib.suppress(ValueError, OSError):
            signal.signal(s, _on_signal)
            _PREVIOUS[s] = cur


def _uninstall() -> None:
    if threading.current_thread() is not threading.main_thread():
        return
    for s, prev in list(_PREVIOUS.items()):
        if signal.getsignal(s) is _on_signal:
            with contextlib.suppress(ValueError, OSError):
                signal.signal(s, prev)
        _PREVIOUS.pop(s, None)


@contextlib.contextmanager
def guard(cleanup: Callable[[], None]) -> Iterator[None]:
    """Run ``cleanup`` on exit, and on SIGINT/SIGTERM before the process ends.

    ``cleanup`` must be idempotent: a signal during or right after it runs it again.
    A SIGINT whose ``KeyboardInterrupt`` was swallowed inside the block (raised
    in a finaliser, where Python only prints it) is raised again at its end.
    """
    key = next(_COUNTER)
    with _LOCK:
        _PENDING[key] = cleanup
        _install()
    try:
        yield
    except BaseException:
        _INTERRUPTED.clear()  # an interrupt, if any, is on its way up
        raise
    finally:
        # Run the action while it is still registered: a signal arriving now re-runs it
        # (actions are idempotent) instead of finding it already unregistered and
        # ending the process before it ran (a left-over temporary folder).
        with _LOCK:
            act = _PENDING.get(key)
        if act is not None:
            with contextlib.suppress(Exception):
                act()
        with _LOCK:
            _PENDING.pop(key, None)
            if not _PENDING:
                _uninstall()
    if _INTERRUPTED:  # a SIGINT's KeyboardInterrupt was lost in the block: raise it now
        _INTERRUPTED.clear()
        raise KeyboardInterrupt


def remove_path(p: Path) -> None:
    if p.is_dir() and not p.is_symlink():
        shutil.rmtree(p, ignore_errors=True)
    elif os.path.lexists(p):
        with contextlib.suppress(OSError):
            os.unlink(p)
