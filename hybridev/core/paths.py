"""Paths as the OS resolves them, and OS errors in one line (used by :mod:`hybridev.core.outputs`).

An output is compared with the inputs of the same run as the files the OS
reads and writes: :func:`resolve_output` resolves symbolic links in the folders
(``ld/../x.csv`` where ``ld`` is a link is not the ``x.csv`` of the current
folder), :func:`real_input` also resolves the last component and a glob's
folder, :func:`same_file` compares device and inode (hard links).
"""

from __future__ import annotations

import errno
import glob
import os
from pathlib import Path

__all__ = ["SYSTEM_ROOTS", "inside", "os_reason", "real_input", "resolve_output", "same_file",
           "system_path"]

SYSTEM_ROOTS = ("/dev", "/proc", "/sys")
"""Folders no output may be written into (device files, kernel interfaces)."""


def inside(child: Path, parent: Path) -> bool:
    """Whether ``child`` is ``parent`` or lies under it (as paths)."""
    try:
        child.relative_to(parent)
    except ValueError:
        return False
    return True


def resolve_output(p: str | os.PathLike) -> Path:
    """The path the OS will write: symlinks in the folders resolved (``ld/../x`` as the OS
    reads it, not collapsed as text); the last component kept as named."""
    raw = os.path.expanduser(os.fspath(p))
    head, tail = os.path.split(raw.rstrip("/") or raw)
    if tail in ("", ".", ".."):
        return Path(os.path.realpath(raw))
    return Path(os.path.realpath(head or ".")) / tail


def real_input(p: str | os.PathLike) -> Path:
    """The real file or folder an input names (a glob: the folder it starts from)."""
    raw = os.path.expanduser(os.fspath(p))
    if glob.has_magic(raw):
        parts = Path(raw).parts
        keep = next(i for i, part in enumerate(parts) if glob.has_magic(part))
        raw = os.path.join(*parts[:keep]) if keep else "."
    return Path(os.path.realpath(raw))


def same_file(a: Path, b: Path) -> bool:
    """Same inode (a hard link, a bind mount) or the same real path."""
    if a == b:
        return True
    try:
        sa, sb = os.stat(a), os.stat(b)
    except OSError:
        return False
    return (sa.st_dev, sa.st_ino) == (sb.st_dev, sb.st_ino)


def system_path(p: Path) -> bool:
    return os.name == "posix" and any(p == Path(r) or inside(p, Path(r)) for r in SYSTEM_ROOTS)


def os_reason(exc: OSError) -> str:
    """One line for an OS error: its text and what to do (name too long, permission, ...)."""
    hints = {errno.ENAMETOOLONG: "shorten the name",
             errno.EACCES: "check the permissions of its folders",
             errno.EPERM: "check the permissions of its folders",
             errno.EROFS: "the file system is read-only: choose another place",
             errno.ENOSPC: "the disk is full: free space or choose another place",
             errno.EDQUOT: "the disk quota is exceeded: free space or choose another place",
             errno.ELOOP: "a symbolic link loops",
             errno.ENOTDIR: "a part of the path is not a folder"}
    text = exc.strerror or str(exc)
    hint = hints.get(exc.errno)
    return f"{text} ({hint})" if hint else text
