"""The marker of folders written by hybridev (used by :mod:`hybridev.core.outputs`).

``_hybridev-manifest.json`` holds ``written_by: "hybridev"``, the ``kind`` of
output (``"model_dir"``, ``"dir"``, ``"merge_dir"``), optional fields such as a
format version, and ``files``: the relative path and SHA-256 of every file
hybridev wrote into the folder.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Callable
from pathlib import Path

__all__ = ["MANIFEST_FILE", "foreign_files", "is_hybridev_dir", "list_files", "read_manifest",
           "sha256_file", "write_manifest"]

MANIFEST_FILE = "_hybridev-manifest.json"
"""Marker of a folder written by hybridev: ``written_by``, ``kind`` and the
SHA-256 of every file in it (``files``: relative path -> hex digest)."""


def sha256_file(path: str | os.PathLike) -> str:
    """Hex SHA-256 of a file, read in 1 MiB blocks."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def read_manifest(folder: str | os.PathLike) -> dict | None:
    """The folder's :data:`MANIFEST_FILE` as a dict, or None when absent or unreadable."""
    p = Path(folder) / MANIFEST_FILE
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError):
        return None
    if (not isinstance(doc, dict) or doc.get("written_by") != "hybridev"
            or not isinstance(doc.get("files"), dict)):
        return None
    return doc


def list_files(folder: Path) -> list[str]:
    """Relative paths of every file (not folder) under ``folder``, sorted."""
    return sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*")
                  if not p.is_dir() or p.is_symlink())


def foreign_files(folder: Path, legacy: Callable[[Path], bool] | None = None) -> list[str]:
    """Files in ``folder`` that hybridev did not write there, or that changed since
    (their SHA-256 differs from the manifest's); empty: safe to replace."""
    files = [f for f in list_files(folder) if f != MANIFEST_FILE]
    if not files:
        return []
    doc = read_manifest(folder)
    if doc is None:
        return [] if legacy is not None and legacy(folder) else files
    listed = doc["files"]
    return [f for f in files if f not in listed or not _unchanged(folder / f, listed[f])]


def _unchanged(path: Path, digest) -> bool:
    if digest == "folder":  # a merged folder's sub-folder: checked by its own manifest
        return True
    try:
        return path.is_file() and not path.is_symlink() and sha256_file(path) == digest
    except OSError:
        return False


def is_hybridev_dir(folder: str | os.PathLike) -> bool:
    """True when ``folder`` carries a manifest listing every file in it."""
    folder = Path(folder)
    return folder.is_dir() and read_manifest(folder) is not None and not foreign_files(folder)


def write_manifest(folder: Path, info: dict, keep: dict | None = None) -> None:
    """Write the manifest of ``folder``: ``info`` fields and the SHA-256 of every file."""
    files = dict(keep or {})
    for rel in list_files(folder):
        if rel != MANIFEST_FILE:
            files[rel] = sha256_file(folder / rel)
    doc = {"written_by": "hybridev", **info, "files": dict(sorted(files.items()))}
    (folder / MANIFEST_FILE).write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
