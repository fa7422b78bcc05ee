"""Merged folder outputs with a journal (``kind="merge_dir"`` of :mod:`hybridev.core.outputs`).

``hybridev demo --out results`` writes several entries into a folder that may
hold the user's own files too; each entry replaces the one of that name that
hybridev wrote there before, other files are kept. The entries move one by
one, so the folder as a whole is made consistent by a journal:

1. the new entries are built in a hidden staging folder
   ``<out>/.hybridev.<pid>.<random>.tmp``;
2. when complete, a journal ``<out>/.hybridev-merge.<pid>.json`` is written
   atomically: the staging folder, the SHA-256 of every new entry and the new
   manifest;
3. the entries move in (a folder by an atomic exchange where the OS has one),
   then the manifest; the journal and the staging folder are removed last.

Before the journal exists, an interrupted run is rolled back (the staging
folder is removed: the old entries never moved). Once it exists, the run is
rolled *forward*: by the signal handler for SIGINT/SIGTERM, and by the next
write to the folder (:func:`recover_merge`) after a SIGKILL, so the folder ends
as the complete new output. An entry is moved only while its content differs
from the journal's digest, so a roll-forward never swaps an entry back.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import re
import tempfile
import warnings
from collections.abc import Callable, Iterator
from pathlib import Path

from hybridev.core.cleanup import guard, remove_path
from hybridev.core.errors import RecoveryWarning
from hybridev.core.manifest import MANIFEST_FILE, read_manifest, sha256_file
from hybridev.core.swap import exchange, fault, pid_alive, recover

__all__ = ["merge_into", "recover_merge", "tree_digest"]

_JOURNAL = re.compile(r"^\.hybridev-merge\.(?P<pid>\d+)\.json$")


def tree_digest(path: Path) -> str | None:
    """SHA-256 of a file, or of a folder's sorted (relative path, file SHA-256) list; None if absent."""
    if not os.path.lexists(path):
        return None
    if not path.is_dir() or path.is_symlink():
        return sha256_file(path) if path.is_file() else "special"
    h = hashlib.sha256()
    for p in sorted(path.rglob("*")):
        if p.is_file() and not p.is_symlink():
            h.update(p.relative_to(path).as_posix().encode() + b"\0")
            h.update(sha256_file(p).encode() + b"\n")
    return "tree:" + h.hexdigest()


def _write_json(path: Path, doc: dict) -> None:
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.{os.getpid()}.", suffix=".tmp",
                               dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            json.dump(doc, fh, indent=1)
            fh.write("\n")
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def _move_in(src: Path, dst: Path) -> None:
    """Put ``src`` at ``dst`` (replacing it); afterwards ``src`` is gone or holds the old entry."""
    if src.is_dir() and dst.is_dir() and not dst.is_symlink():
        if exchange(src, dst):
            return
        remove_path(dst)
    elif dst.is_dir() and not dst.is_symlink():
        remove_path(dst)
    os.replace(src, dst)


def _roll_forward(target: Path, journal: Path) -> bool:
    """Finish the merge that ``journal`` describes; True when it did."""
    try:
        doc = json.loads(journal.read_text(encoding="utf-8"))
        staging = target / doc["staging"]
        entries, manifest = dict(doc["entries"]), dict(doc["manifest"])
    except (OSError, ValueError, KeyError, TypeError):
        remove_path(journal)
        return False
    for name, digest in entries.items():
        src, dst = staging / name, target / name
        if tree_digest(dst) != digest and tree_digest(src) == digest:
            _move_in(src, dst)
        fault("merge.moved")
    _write_json(target / MANIFEST_FILE, manifest)
    fault("merge.manifest")
    remove_path(staging)
    remove_path(journal)
    fault("merge.done")
    return True


def recover_merge(target: str | os.PathLike) -> list[str]:
    """Finish the merges of crashed runs into ``target``, drop their staging folders; notes."""
    target = Path(target)
    notes: list[str] = []
    if not target.is_dir():
        return notes
    with contextlib.suppress(OSError):
        for entry in sorted(os.listdir(target)):
            m = _JOURNAL.match(entry)
            if m is None or pid_alive(int(m.group("pid"))):
                continue
            if _roll_forward(target, target / entry):
                notes.append(f"completed the output {str(target)!r} of an interrupted earlier "
                             f"run from its journal {entry!r}")
    for note in notes:
        warnings.warn(note, RecoveryWarning, stacklevel=3)
    return notes + recover(target / "hybridev")


def merge_into(target: Path, info: dict, check: Callable[[list[str]], None]) -> Iterator[Path]:
    """Generator behind ``output_dir(kind="merge_dir")``: yield a staging folder, then merge it.

    ``check(names)`` re-checks, just before the merge, that every entry may be replaced.
    """
    created = not os.path.lexists(target)
    target.mkdir(parents=True, exist_ok=True)
    recover_merge(target)
    tmp = Path(tempfile.mkdtemp(prefix=f".hybridev.{os.getpid()}.", suffix=".tmp", dir=target))
    tmp.chmod(0o755)
    journal = target / f".hybridev-merge.{os.getpid()}.json"

    def cleanup() -> None:
        if journal.exists():
            _roll_forward(target, journal)  # past the point of no return: finish it
        remove_path(tmp)
        if created and not (target / MANIFEST_FILE).exists():
            with contextlib.suppress(OSError):
                target.rmdir()  # only if still empty

    with guard(cleanup):
        yield tmp
        fault("merge.written")
        names = sorted(p.name for p in tmp.iterdir())
        check(names)
        old_doc = read_manifest(target) or {"files": {}}
        files = {k: v for k, v in old_doc["files"].items() if os.path.lexists(target / k)}
        entries = {}
        for name in names:
            entries[name] = tree_digest(tmp / name)
            files[name] = "folder" if (tmp / name).is_dir() else sha256_file(tmp / name)
        manifest = {"written_by": "hybridev", **info, "files": dict(sorted(files.items()))}
        _write_json(journal, {"staging": tmp.name, "entries": entries, "manifest": manifest})
        fault("merge.journal")
        _roll_forward(target, journal)
