"""Which single files hybridev wrote (used by :mod:`hybridev.core.outputs`).

A file output (``--out FILE``, ``--plot FILE``, ``--trips-out FILE``) may
replace an existing file only if hybridev wrote that file and nobody changed it
since. Each folder that receives a file output gets a small register,
:data:`REGISTER_FILE`, with the SHA-256 of every file hybridev wrote there
(name -> hex digest). A file not in the register, or whose content no longer
matches, is the user's: hybridev refuses to overwrite it.

The register is itself written atomically (temporary name, then
:func:`os.replace`). Two runs writing files into one folder at the same moment
may lose one entry; the only effect is that the next run refuses to replace
that file (the safe direction).
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

from hybridev.core.manifest import sha256_file

__all__ = ["REGISTER_FILE", "is_owned", "record_owned"]

REGISTER_FILE = ".hybridev-files.json"
"""Per-folder register of the single files hybridev wrote: ``{"written_by":
"hybridev", "files": {name: sha256}}``."""


def _read(folder: Path) -> dict[str, list[str]]:
    try:
        doc = json.loads((folder / REGISTER_FILE).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError):
        return {}
    if not isinstance(doc, dict) or doc.get("written_by") != "hybridev":
        return {}
    files = doc.get("files")
    if not isinstance(files, dict):
        return {}
    return {str(k): [str(d) for d in v] if isinstance(v, list) else [str(v)]
            for k, v in files.items()}


def is_owned(path: str | os.PathLike) -> bool:
    """True when ``path`` is a regular file hybridev wrote and nobody changed since.

    Examples
    --------
    >>> import tempfile
    >>> d = Path(tempfile.mkdtemp())
    >>> _ = (d / "mine.csv").write_text("a\\n1\\n")
    >>> is_owned(d / "mine.csv")
    False
    >>> record_owned(d / "mine.csv"); is_owned(d / "mine.csv")
    True
    >>> _ = (d / "mine.csv").write_text("a\\n2\\n"); is_owned(d / "mine.csv")
    False
    """
    p = Path(path)
    if not p.is_file() or p.is_symlink():
        return False
    digests = _read(p.parent).get(p.name, [])
    try:
        return bool(digests) and sha256_file(p) in digests
    except OSError:
        return False


def record_owned(path: str | os.PathLike, *, pending: str | os.PathLike | None = None) -> None:
    """Add ``path`` (just written by hybridev) to its folder's register.

    ``pending``: the finished temporary file about to replace ``path``; its
    digest is registered *beside* the current one, so that a crash between
    the replacement and the final record leaves a file the next run may replace.

    A register that cannot be written is not an error: the file itself is
    complete, and the next run will only refuse to overwrite it.
    """
    p = Path(path)
    files = _read(p.parent)
    try:
        if pending is None:
            files[p.name] = [sha256_file(p)]
        else:
            now = sha256_file(p) if p.is_file() and not p.is_symlink() else None
            keep = [now] if now is not None and now in files.get(p.name, []) else []
            files[p.name] = [*keep, sha256_file(pending)]
        doc = {k: v[0] if len(v) == 1 else v for k, v in sorted(files.items())}
        fd, tmp = tempfile.mkstemp(prefix=f"{REGISTER_FILE}.{os.getpid()}.", suffix=".tmp",
                                   dir=p.parent)
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            json.dump({"written_by": "hybridev", "files": doc}, fh, indent=1)
        os.chmod(tmp, 0o644)
        os.replace(tmp, p.parent / REGISTER_FILE)
    except OSError:
        try:
            os.unlink(tmp)
        except (OSError, UnboundLocalError):
            pass
