"""Safe outputs: every file or folder hybridev writes goes through this module.

The rules (also in the README, section "Safety"):

* **Check before the work.** :func:`check_output` is called by every command
  and public writer *before* any computation. A bad path raises a
  :class:`ValueError` naming the option (``--out``, ``--plot``, ...): a
  missing or non-folder parent that cannot be created, no write permission,
  a wrong extension for the format, a path that is also an input (or inside
  an input folder, or a folder holding an input), a file path that is a
  folder, a folder path that is a file.
* **Atomic, and crash-consistent.** Everything is written into a hidden
  temporary name in the same folder and moved into place only when complete: a
  file by :func:`os.replace`, a folder by an atomic exchange with the old one
  (``renameat2(RENAME_EXCHANGE)`` on Linux; a journalled two-step rename
  elsewhere), so at every instant the path holds the complete old or the
  complete new output, whatever ends the process (an error, SIGINT, SIGTERM,
  SIGKILL). On an error or SIGINT/SIGTERM the temporary files are removed at
  once; after a SIGKILL the next write to that place removes (or restores) them
  and says so (:mod:`hybridev.core.swap`, :mod:`hybridev.core.merge`).
* **Never over an input.** Outputs and inputs are compared as the files the OS
  resolves (symlinks in the folders, ``..``, hard links by device and inode),
  and a folder output may not lie inside an input folder (a data set would read
  it back). Nothing is written under ``/dev``, ``/proc`` or ``/sys``, nor over a
  device file, FIFO or socket. OS errors (name too long, permission, read-only
  or full disk) are ``ValueError`` naming the option.
* **Never destroy what we did not write.** A *file* output replaces an
  existing file only if hybridev wrote it there and nobody changed it since
  (the folder's register :data:`~hybridev.core.owned.REGISTER_FILE`, with the
  SHA-256 of each file written; :mod:`hybridev.core.owned`); never a file of
  the user's, a folder or an input. A *folder* output (``kind="model_dir"`` or ``"dir"``: a saved
  model, a report) replaces an existing folder only if it is empty or carries
  this package's marker :data:`MANIFEST_FILE` listing every file in it with its
  SHA-256 (a folder hybridev wrote, and nothing added or changed since). A *merged* folder
  (``kind="merge_dir"``, ``hybridev demo``) keeps the files the user put
  there and replaces only the entries hybridev wrote there before.

API
---
``check_output(path, option=..., kind="file"|"model_dir"|"dir"|"merge_dir",
suffixes=..., inputs=[...], names=[...]) -> Path``
    Validate an output path before the work.
``atomic_file(path, option=...)``
    Context manager yielding a temporary path; moved to ``path`` on success
    (an existing ``path`` only if hybridev wrote it).
``atomic_replace(path, option=...)``
    The same without the ownership rule, for files inside folder outputs and
    the workflow scripts' own committed outputs.
``write_table(df, path, option=...)`` (CSV text cells that a spreadsheet would run
as a formula get a leading ``'``: :func:`neutralise_formulas`), ``write_text(text, path, option=...)``,
``save_figure(fig, path, option=...)``
    One-call atomic writers (a failed write raises ``ValueError`` naming the option).
``output_dir(path, option=..., kind=..., manifest=None)``
    Context manager yielding a temporary folder; on success a manifest with
    the SHA-256 of every file is added and the folder moved into place.
``read_manifest(folder)``, ``is_hybridev_dir(folder)``
    Inspect a folder's marker (from :mod:`hybridev.core.manifest`).

Clean-up on signals lives in :mod:`hybridev.core.cleanup`; safe ``.npz``
reading in :mod:`hybridev.core.npz`. Callers that add inputs or outputs (new
CLI options) pass every input path to ``inputs=`` and call
:func:`check_output` before reading anything large.

Module size (about 440 lines, over the package's 400-line guide): every rule on
what may be written where is here, in one place to audit; its helpers with a job of
their own live beside it (:mod:`hybridev.core.manifest`, :mod:`hybridev.core.owned`,
:mod:`hybridev.core.cleanup`, :mod:`hybridev.core.swap`, :mod:`hybridev.core.merge`,
:mod:`hybridev.core.paths`, :mod:`hybridev.core.csvsafe`).
"""

from __future__ import annotations

import contextlib
import os
import stat
import tempfile
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path

from hybridev.core.cleanup import guard, remove_path
from hybridev.core.csvsafe import neutralise_formulas
from hybridev.core.manifest import (
    MANIFEST_FILE,
    foreign_files,
    is_hybridev_dir,
    read_manifest,
    sha256_file,
    write_manifest,
)
from hybridev.core.merge import merge_into, recover_merge
from hybridev.core.owned import REGISTER_FILE, is_owned, record_owned
from hybridev.core.paths import (
    SYSTEM_ROOTS,
    inside,
    os_reason,
    real_input,
    resolve_output,
    same_file,
    system_path,
)
from hybridev.core.swap import fault, recover, replace_dir, undo_dir

__all__ = ["FIGURE_SUFFIXES", "MANIFEST_FILE", "REGISTER_FILE", "TABLE_SUFFIXES", "atomic_file",
           "atomic_replace", "check_output", "is_hybridev_dir", "neutralise_formulas", "os_reason",
           "output_dir", "read_manifest", "save_figure", "sha256_file", "write_table",
           "write_text"]

TABLE_SUFFIXES = (".csv", ".parquet", ".pq")
FIGURE_SUFFIXES = (".png", ".svg", ".pdf")
_KINDS = ("file", "model_dir", "dir", "merge_dir")


# -- checks -----------------------------------------------------------------------------------
# A new folder named like a file is almost always a mistake (``--out model.csv``).
_FILE_LIKE_SUFFIXES = (".csv", ".parquet", ".pq", ".json", ".html", ".xlsx", ".png", ".pdf",
                       ".svg", ".txt")

def check_output(path: str | os.PathLike, *, option: str = "--out", kind: str = "file",
                 suffixes: Iterable[str] | None = None,
                 inputs: Iterable[str | os.PathLike | None] = (),
                 names: Iterable[str] = (),
                 legacy: Callable[[Path], bool] | None = None) -> Path:
    """Check an output path before any work; return it as an absolute :class:`~pathlib.Path`.

    Parameters
    ----------
    path : path-like
        The output file or folder.
    option : str
        Name shown in the error (``"--out"``, ``"--plot"``, ``"path"``).
    kind : {"file", "model_dir", "dir", "merge_dir"}
        ``file``: a single file; an existing file is replaced only if hybridev
        wrote it and it is unchanged since (:func:`hybridev.core.owned.is_owned`).
        ``model_dir``/``dir``: a folder replaced as a whole, allowed only when
        absent, empty or written by hybridev (:data:`MANIFEST_FILE`).
        ``merge_dir``: a folder into which the entries ``names`` are written;
        other files in it are kept, and each of ``names`` that exists must have
        been written there by hybridev.
    suffixes : iterable of str, optional
        Allowed extensions of a file (case-insensitive).
    inputs : iterable of path-like
        Input files or folders of the same run; the output may not be one of
        them, lie inside one, or (for folders) hold one.
    names : iterable of str
        For ``merge_dir``: the top-level entries that will be written.
    legacy : callable, optional
        ``legacy(folder) -> bool``: recognises a folder written by an older
        hybridev without a manifest (e.g. a model of format version 1).

    Raises
    ------
    ValueError
        Naming ``option``, the path and the reason.

    Examples
    --------
    >>> import tempfile
    >>> d = Path(tempfile.mkdtemp())
    >>> check_output(d / "p.csv", suffixes=TABLE_SUFFIXES).name
    'p.csv'
    >>> check_output(d / "p.xlsx", suffixes=TABLE_SUFFIXES)
    Traceback (most recent call last):
    ...
    ValueError: --out=... must end in one of ['.csv', '.parquet', '.pq']; got '.xlsx'
    """
    if kind not in _KINDS:
        raise ValueError(f"kind={kind!r}; allowed: {list(_KINDS)}")
    raw = os.fspath(path) if isinstance(path, str | os.PathLike) else path
    if not isinstance(raw, str) or raw.strip() == "":
        raise ValueError(f"{option}={path!r} must be a non-empty path")
    if "\0" in raw:
        raise ValueError(f"{option}={raw!r} contains a NUL character")
    what = f"{option}={raw!r}"
    try:
        return _check(raw, what, kind, suffixes, inputs, names, legacy)
    except OSError as exc:
        raise ValueError(f"{what} cannot be used: {os_reason(exc)}") from exc


def _check(raw: str, what: str, kind: str, suffixes, inputs, names, legacy) -> Path:
    p = resolve_output(raw)
    rp = Path(os.path.realpath(p))
    if system_path(rp) or system_path(p):
        raise ValueError(f"{what} lies under {', '.join(SYSTEM_ROOTS)}: hybridev writes "
                         "regular files only; choose a path in your own folders")
    for inp in inputs:
        if inp is None:
            continue
        q = real_input(inp)
        if same_file(q, rp):
            raise ValueError(f"{what} is also an input of this run ({str(inp)!r}); hybridev "
                             "never writes over its input: choose another path")
        if kind != "file" and inside(q, rp):
            raise ValueError(f"{what} holds the input {str(inp)!r}; choose another path")
        if q.is_dir() and inside(rp, q):
            raise ValueError(f"{what} lies inside the input folder {str(inp)!r} (the next "
                             "run would read it back as input); choose another path")
    if kind == "merge_dir":
        recover_merge(p)
    recover(p, names=(REGISTER_FILE[1:],) if kind == "file" else ())
    if kind == "file":
        if raw.endswith(("/", os.sep)) or p.is_dir():
            raise ValueError(f"{what} is a directory; give a file name")
        if suffixes is not None:
            allowed = [s.lower() for s in suffixes]
            if p.suffix.lower() not in allowed:
                raise ValueError(f"{what} must end in one of {allowed}; got "
                                 f"{p.suffix or 'no extension'!r}")
        if os.path.lexists(p) and (not stat.S_ISREG(os.lstat(p).st_mode)):
            raise ValueError(f"{what} exists and is not a regular file")
        if os.path.lexists(p) and not is_owned(p):
            raise ValueError(_foreign_file(what))
    else:
        if os.path.lexists(p) and not p.is_dir():
            raise ValueError(f"{what} exists and is not a folder; hybridev never replaces a "
                             "file with a folder: choose another path")
        if p.is_dir() and p.is_symlink():
            raise ValueError(f"{what} is a symbolic link; give the real folder")
        if p.is_dir() and kind in ("model_dir", "dir") and inside(Path(os.getcwd()), rp):
            raise ValueError(f"{what} is the current folder (or holds it); it would be "
                             "replaced as a whole: give a new folder name")
        if p.is_dir() and kind in ("model_dir", "dir"):
            doc = read_manifest(p) or {}
            other = doc.get("kind", kind)
            if other != kind:
                what_is = ("a saved model" if other == "model_dir"
                           else f"a hybridev {doc.get('content', 'output')} folder")
                raise ValueError(f"{what} holds {what_is}, not this kind of output; "
                                 "hybridev refuses to replace it: give a new folder name")
            bad = foreign_files(p, legacy)
            if bad:
                raise ValueError(
                    f"{what} is an existing folder with files hybridev did not write there, or "
                    f"changed since (e.g. {bad[0]!r}); it would be replaced as a whole, so hybridev refuses: "
                    "give a new folder name")
        if p.is_dir() and kind == "merge_dir":
            doc = read_manifest(p)
            old = doc is None and legacy is not None and legacy(p)
            listed = dict.fromkeys(names, "") if old else dict((doc or {"files": {}})["files"])
            for name in names:
                q = p / name
                if not os.path.lexists(q):
                    continue
                if q.is_dir() and not q.is_symlink():
                    ours = name in listed and (old or not foreign_files(q))
                else:  # a file: unchanged since hybridev wrote it
                    ours = name in listed and (old or (stat.S_ISREG(os.lstat(q).st_mode)
                                                       and listed[name] == sha256_file(q)))
                if not ours:
                    raise ValueError(f"{what}: {str(q)!r} exists and was not written there by "
                                     "hybridev (or was changed since); move it away or choose another folder")
    anc = p.parent
    while not os.path.lexists(anc) and anc != anc.parent:
        anc = anc.parent
    if not anc.is_dir():
        raise ValueError(f"{what} is not writable: {str(anc)!r} is not a directory")
    if not os.access(anc, os.W_OK | os.X_OK):
        raise ValueError(f"{what} is not writable: no write permission in {str(anc)!r}")
    if kind != "file" and not p.exists() and p.suffix.lower() in _FILE_LIKE_SUFFIXES:
        raise ValueError(f"{what} looks like a file name ({p.suffix!r}); this output is a "
                         "folder: give a folder name")
    return p


def _foreign_file(what: str) -> str:
    return (f"{what} exists and was not written by hybridev (or was changed since); "
            "hybridev never overwrites a file it did not create: move it away or choose "
            "another path")


def _could_not(option: str, path, exc: BaseException) -> ValueError:
    return ValueError(f"{option}={os.fspath(path)!r} could not be written: {exc}")


# -- writers ----------------------------------------------------------------------------------
@contextlib.contextmanager
def atomic_file(path: str | os.PathLike, *, option: str = "--out") -> Iterator[Path]:
    """Yield a temporary file path in the target's folder; moved to ``path`` on success.

    An existing ``path`` is replaced only if hybridev wrote it and it is
    unchanged since (else ValueError naming ``option``, and nothing is
    written); the new file is added to the folder's register
    (:mod:`hybridev.core.owned`).

    Examples
    --------
    >>> import tempfile
    >>> d = Path(tempfile.mkdtemp())
    >>> with atomic_file(d / "a.txt") as tmp:
    ...     _ = tmp.write_text("hi")
    >>> (d / "a.txt").read_text(), sorted(p.name for p in d.iterdir())
    ('hi', ['.hybridev-files.json', 'a.txt'])
    >>> with atomic_file(d / "a.txt") as tmp:  # hybridev wrote it: may be replaced
    ...     _ = tmp.write_text("again")
    >>> _ = (d / "b.txt").write_text("the user's")
    >>> with atomic_file(d / "b.txt") as tmp:
    ...     _ = tmp.write_text("no")
    Traceback (most recent call last):
    ...
    ValueError: --out=... exists and was not written by hybridev (or was changed since); ...
    """
    with atomic_replace(path, option, register=True) as tmp:
        yield tmp


@contextlib.contextmanager
def atomic_replace(path, option: str = "path", *, register: bool = False) -> Iterator[Path]:
    """The atomic write under :func:`atomic_file`, without its ownership rule by default.

    ``register=False``: ``path`` is replaced whoever wrote it and is not added to the
    register. For files inside a folder output (its manifest, covered by the
    folder's own marker) and for the outputs that the project's own workflow
    scripts (``evaluation/``, ``calibration/``, ``benchmarks/``) regenerate in place.
    """
    path = resolve_output(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        recover(path, names=(REGISTER_FILE[1:],))  # leftovers of a crashed earlier run
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.{os.getpid()}.", suffix=".tmp",
                                   dir=path.parent)
        os.close(fd)
        os.chmod(tmp, 0o644)  # mkstemp makes it private; the result is an ordinary file
    except OSError as exc:
        raise _could_not(option, path, exc) from exc
    tmp = Path(tmp)
    with guard(lambda: remove_path(tmp)):
        try:
            yield tmp
            fault("file.written")
            if register and os.path.lexists(path) and not is_owned(path):
                raise ValueError(_foreign_file(f"{option}={str(path)!r}"))
            if register:  # the register accepts both versions while the file is replaced
                record_owned(path, pending=tmp)
                fault("file.pending")
            os.replace(tmp, path)
            fault("file.replaced")
        except OSError as exc:
            raise _could_not(option, path, exc) from exc
    if register:
        record_owned(path)
        fault("file.done")


def write_table(df, path: str | os.PathLike, *, option: str = "--out") -> None:
    """Write a DataFrame as CSV or Parquet (by suffix), atomically.

    Examples
    --------
    >>> import tempfile, pandas as pd
    >>> d = Path(tempfile.mkdtemp())
    >>> write_table(pd.DataFrame({"a": [1]}), d / "t.csv")
    >>> (d / "t.csv").read_text().split()
    ['a', '1']
    """
    with atomic_file(path, option=option) as tmp:
        if Path(path).suffix.lower() in (".parquet", ".pq"):
            df.to_parquet(tmp, index=False)
        else:
            neutralise_formulas(df).to_csv(tmp, index=False)


def write_text(text: str, path: str | os.PathLike, *, option: str = "--out") -> None:
    """Write UTF-8 text (JSON, HTML, Markdown), atomically.

    Examples
    --------
    >>> import tempfile
    >>> d = Path(tempfile.mkdtemp())
    >>> write_text("{}", d / "s.json")
    >>> (d / "s.json").read_text()
    '{}'
    """
    with atomic_file(path, option=option) as tmp:
        tmp.write_text(text, encoding="utf-8")


def save_figure(fig, path: str | os.PathLike, *, option: str = "--plot", **kwargs) -> None:
    """Save a matplotlib figure atomically, in the format given by the suffix."""
    fmt = Path(path).suffix.lower().lstrip(".") or None
    with atomic_file(path, option=option) as tmp:
        fig.savefig(tmp, format=fmt, **kwargs)


@contextlib.contextmanager
def output_dir(path: str | os.PathLike, *, option: str = "--out", kind: str = "dir",
               manifest: dict | None = None, inputs: Iterable = (),
               legacy: Callable[[Path], bool] | None = None,
               names: Iterable[str] = ()) -> Iterator[Path]:
    """Yield a temporary folder that becomes ``path`` on success, with a manifest.

    ``kind="model_dir"`` or ``"dir"``: ``path`` is replaced as a whole (allowed
    only as :func:`check_output` says). ``kind="merge_dir"``: each top-level
    entry of the temporary folder replaces the entry of that name in ``path``
    (checked the same way); other files in ``path`` are kept. ``manifest``:
    extra fields of :data:`MANIFEST_FILE` (e.g. a format version).

    The check is repeated at the start, so a direct caller is protected too.
    On error or SIGINT/SIGTERM nothing is left behind and ``path`` is unchanged
    (a signal in the middle of the final swap restores the previous folder).

    Examples
    --------
    >>> import tempfile
    >>> d = Path(tempfile.mkdtemp())
    >>> with output_dir(d / "m", kind="model_dir") as tmp:
    ...     _ = (tmp / "x.txt").write_text("1")
    >>> sorted(p.name for p in (d / "m").iterdir())
    ['_hybridev-manifest.json', 'x.txt']
    """
    info = {"kind": kind, **(manifest or {})}
    target = check_output(path, option=option, kind=kind, inputs=inputs, legacy=legacy,
                          names=names)
    if kind == "merge_dir":
        def recheck(entries: list[str]) -> None:
            check_output(target, option=option, kind=kind, names=entries, legacy=legacy)

        try:
            yield from merge_into(target, info, recheck)
        except OSError as exc:
            raise _could_not(option, path, exc) from exc
        return
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.{os.getpid()}.", suffix=".tmp",
                                    dir=target.parent))
        tmp.chmod(0o755)
    except OSError as exc:
        raise _could_not(option, path, exc) from exc
    state: dict = {"old": None}

    with guard(lambda: undo_dir(tmp, target, state)):
        try:
            yield tmp
        except OSError as exc:
            raise _could_not(option, path, exc) from exc
        try:
            fault("dir.written")
            write_manifest(tmp, info)
            fault("dir.manifest")
            check_output(target, option=option, kind=kind, legacy=legacy)  # still replaceable
            replace_dir(tmp, target, state)
            undo_dir(tmp, target, state)  # removes the old folder
            fault("dir.done")
        except OSError as exc:
            raise _could_not(option, path, exc) from exc
