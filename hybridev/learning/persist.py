"""Model directories on disk: one JSON document plus one ``.npz`` of arrays, no pickle.

:func:`save_model` / :func:`load_model` implement ``HybridModel.save`` and
``HybridModel.load``. Layout of a model directory (format version 3)::

    model.json              format name and version, hybridev version, configuration,
                            vehicle, training summary, each component's document under
                            ``components``, and the name and SHA-256 of the array file
    arrays.npz              numpy arrays, ``<component>.<name>``: ``learner.*`` (network
                            weights, scalers, loss curves), ``physics.*`` (posterior
                            draws, discrepancy), ``domain.*``, ``calibrator.*`` (scores,
                            Mondrian bins, CV+ fold networks and physics),
                            ``planned.*`` (planned-trip scores and mean correction; only
                            when fitted on logged traces), ``gap_rate.*`` (the learned
                            out-of-domain widening rate); absent when nothing was fitted
                            (the stacking gate, ``gate``, has a document only; models
                            without it load with weight 1)
    _hybridev-manifest.json  the marker of a folder written by hybridev
                            (:mod:`hybridev.core.outputs`): ``kind: "model_dir"``,
                            format name and version, and the SHA-256 of every file

Each component of the model (:meth:`hybridev.HybridModel.components`) saves and loads
its own state: ``to_arrays() -> (json_doc, arrays)`` and ``set_arrays(json_doc,
arrays)``. Subclasses may keep more state through ``model._extra_state() ->
(json_dict, arrays)`` and ``model._set_extra_state(json_dict, arrays)``, stored under
``"extra"`` and as ``extra.*`` arrays.

Writing goes through :func:`hybridev.core.outputs.output_dir`: atomic (a failed
or interrupted save leaves any previous directory untouched and no temporary
folder), and an existing folder is replaced only when it is a model (or other
folder) written by hybridev, never a user's folder or file.

Reading verifies before it allocates: the manifest's SHA-256 of every file
(any changed byte is refused), then the ``.npz`` member count, each member's
``.npy`` header (dtype, shape) against the bytes stored and the size limits
:data:`MAX_ARRAYS` and :data:`MAX_ARRAY_BYTES`, then the network size implied
by the configuration against the stored weights. Every failure is a
``ValueError`` naming the file and the problem: missing or unreadable files,
invalid JSON, another format or format version, a model written by another
major version of hybridev, a checksum mismatch (corruption, truncation), and
wrong names or shapes. Models of format versions 1 (no manifest; only the
array file is checksummed) and 2 (the network and its scalers at the top level, the
rest under ``extra``) still load and predict the same (``tests/learning/fixtures``); a
model saved without ``planned`` / ``gap_rate`` gets none (the fixed widening rate, and a
trip without its trace is out of the domain when the model needs one).
"""

from __future__ import annotations

import dataclasses
import json
import os
import re
from pathlib import Path

import numpy as np

from hybridev.core.npz import read_npz
from hybridev.core.outputs import (
    MANIFEST_FILE,
    check_output,
    output_dir,
    read_manifest,
    sha256_file,
)
from hybridev.learning.components import restore
from hybridev.physics.params import VehicleParams

__all__ = ["ARRAYS_FILE", "DOC_FILE", "FORMAT_NAME", "FORMAT_VERSION", "MAX_ARRAYS",
           "MAX_ARRAY_BYTES", "check_model_path", "load_model", "read_model_dir", "save_model", "write_model_dir"]

DOC_FILE = "model.json"
ARRAYS_FILE = "arrays.npz"
FORMAT_NAME = "hybridev.learning.model"
"""Format name of a saved :class:`hybridev.HybridModel` (or subclass)."""
FORMAT_VERSION = 3
"""Version of that format (3: state by component; 2: with a manifest of SHA-256 sums);
versions 1 and 2 are still read, other versions are refused."""
READ_VERSIONS = (1, 2, 3)
MAX_ARRAYS = 4096
"""At most this many arrays in ``arrays.npz``."""
MAX_ARRAY_BYTES = 1 << 30
"""At most this many bytes of arrays in total (1 GiB), and at most 64 times the
size of the ``.npz`` file plus 16 MiB (a small file cannot claim huge arrays)."""
MAX_DOC_BYTES = 64 << 20
"""At most this size of ``model.json`` and of the manifest (64 MiB)."""


def _major(version: str) -> int:
    return int(str(version).split(".")[0])


def _sha256(path: Path) -> str:
    return sha256_file(path)


def _legacy_model(folder: Path) -> bool:
    """A model folder of format version 1 (no manifest): model.json (+ arrays.npz) only."""
    names = {p.name for p in folder.iterdir()}
    if not names <= {DOC_FILE, ARRAYS_FILE} or DOC_FILE not in names:
        return False
    try:
        doc = json.loads((folder / DOC_FILE).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError):
        return False
    return isinstance(doc, dict) and str(doc.get("format", "")).startswith("hybridev")


def check_model_path(path: str | os.PathLike, *, option: str = "path",
                     inputs=()) -> Path:
    """Check, before any work, that a model may be saved at ``path``.

    ``path`` must be new, an empty folder or a model folder hybridev wrote, and
    not one of ``inputs`` (:func:`hybridev.core.outputs.check_output`).

    Examples
    --------
    >>> import tempfile
    >>> d = Path(tempfile.mkdtemp())
    >>> (d / "notes.txt").write_text("mine")
    4
    >>> check_model_path(d, option="--out")
    Traceback (most recent call last):
    ...
    ValueError: --out=... is an existing folder with files hybridev did not write there...
    """
    return check_output(path, option=option, kind="model_dir", inputs=inputs,
                        legacy=_legacy_model)


def write_model_dir(path: str | os.PathLike, doc: dict, arrays: dict[str, np.ndarray] | None,
                    *, option: str = "path") -> None:
    """Write ``doc`` (JSON-serialisable) and ``arrays`` to the directory ``path``, atomically.

    ``doc`` gains ``hybridev_version``, ``arrays_file`` and ``arrays_sha256``;
    the folder gains the manifest (SHA-256 of both files, ``doc["format"]``
    and ``doc["format_version"]``). An existing folder is replaced only when
    hybridev wrote it (:func:`hybridev.core.outputs.check_output`, kind
    ``"model_dir"``); otherwise a ``ValueError`` names ``option``.

    Examples
    --------
    >>> import tempfile
    >>> d = tempfile.mkdtemp()
    >>> write_model_dir(d + "/m", {"format": "demo", "format_version": 1}, {"x": np.ones(2)})
    >>> doc, arr = read_model_dir(d + "/m", format_name="demo", format_version=1)
    >>> arr["x"].tolist()
    [1.0, 1.0]
    """
    from hybridev import __version__

    doc = dict(doc, hybridev_version=__version__)
    info = {"format": doc.get("format"), "format_version": doc.get("format_version")}
    with output_dir(path, option=option, kind="model_dir", manifest=info,
                    legacy=_legacy_model) as tmp:
        if arrays is not None:
            with open(tmp / ARRAYS_FILE, "wb") as fh:
                np.savez_compressed(fh, **arrays)
            doc["arrays_file"] = ARRAYS_FILE
            doc["arrays_sha256"] = _sha256(tmp / ARRAYS_FILE)
        else:
            doc["arrays_file"] = None
        (tmp / DOC_FILE).write_text(json.dumps(doc, indent=1, allow_nan=False) + "\n",
                                    encoding="utf-8")


def _read_json(path: Path) -> dict:
    try:
        size = path.stat().st_size
        if size > MAX_DOC_BYTES:
            raise ValueError(f"{str(path)!r} is {size} bytes, more than the limit "
                             f"{MAX_DOC_BYTES}")
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, RecursionError) as exc:
        raise ValueError(f"{str(path)!r} is not valid JSON (corrupted or truncated?): "
                         f"{exc}") from exc
    if not isinstance(doc, dict):
        raise ValueError(f"{str(path)!r} must hold a JSON object; got {type(doc).__name__}")
    return doc


def _verify_manifest(path: Path, doc: dict, format_name: str, format_version: int) -> None:
    """Check the manifest of a format-2 folder: its fields and every file's SHA-256."""
    man_path = path / MANIFEST_FILE
    if not man_path.is_file():
        raise ValueError(f"{str(man_path)!r} is missing: a model of format_version "
                         f"{doc.get('format_version')} carries a manifest of SHA-256 sums")
    man = _read_json(man_path)
    if read_manifest(path) is None:
        raise ValueError(f"{str(man_path)!r} is not a hybridev manifest")
    if (man.get("kind") != "model_dir" or man.get("format") != format_name
            or man.get("format_version") != format_version):
        raise ValueError(f"{str(man_path)!r} describes kind={man.get('kind')!r}, format="
                         f"{man.get('format')!r}, format_version={man.get('format_version')!r}; "
                         f"expected 'model_dir', {format_name!r}, {format_version}")
    files = man["files"]
    need = {DOC_FILE} | ({ARRAYS_FILE} if doc.get("arrays_file") is not None else set())
    missing = sorted(need - set(files))
    if missing:
        raise ValueError(f"{str(man_path)!r} does not list {missing[0]!r}")
    for name, digest in files.items():
        f = path / name
        if not isinstance(name, str) or "/" in name or name.startswith("."):
            raise ValueError(f"{str(man_path)!r} lists an invalid file name {name!r}")
        if not f.is_file():
            raise ValueError(f"{str(f)!r} is missing (listed in {MANIFEST_FILE})")
        if _sha256(f) != digest:
            raise ValueError(f"{str(f)!r} does not match its SHA-256 in {MANIFEST_FILE} "
                             "(corrupted, truncated or edited)")


def read_model_dir(path: str | os.PathLike, *, format_name: str, format_version: int
                   ) -> tuple[dict, dict[str, np.ndarray] | None]:
    """Read a directory written by :func:`write_model_dir`, checking format and integrity.

    ``format_version`` is the current version; for the model format the older
    :data:`READ_VERSIONS` are read too, for other formats of version 2 version 1
    (version 1: without a manifest).

    Returns
    -------
    doc : dict
    arrays : dict of str to numpy.ndarray, or None when the model stored none

    Raises
    ------
    ValueError
        Naming the file and the problem.
    """
    path = Path(path)
    doc_path = path / DOC_FILE
    if not path.is_dir():
        raise ValueError(f"model directory {str(path)!r} does not exist or is not a directory")
    if not doc_path.is_file():
        raise ValueError(f"{str(doc_path)!r} is missing: {str(path)!r} is not a saved model")
    doc = _read_json(doc_path)
    if doc.get("format") != format_name:
        raise ValueError(f"{str(doc_path)!r} has format={doc.get('format')!r}; "
                         f"expected {format_name!r}")
    if format_name == FORMAT_NAME and format_version == FORMAT_VERSION:
        readable = READ_VERSIONS
    else:
        readable = (1, format_version) if format_version == 2 else (format_version,)
    version = doc.get("format_version")
    if isinstance(version, bool) or version not in readable:
        raise ValueError(f"{str(doc_path)!r} has format_version={version!r}; "
                         f"this hybridev reads format_version {' or '.join(map(str, readable))}")
    from hybridev import __version__

    saved = doc.get("hybridev_version")
    try:
        other_major = _major(saved) != _major(__version__)
    except (TypeError, ValueError):
        raise ValueError(f"{str(doc_path)!r} has an invalid hybridev_version={saved!r}") from None
    if other_major:
        raise ValueError(f"{str(doc_path)!r} was written by hybridev {saved}; this is hybridev "
                         f"{__version__} (another major version): re-fit the model")
    if version >= 2:  # refusals above need no trust; everything below is verified
        _verify_manifest(path, doc, format_name, version)
    name = doc.get("arrays_file")
    if name is None:
        return doc, None
    if name != ARRAYS_FILE:
        raise ValueError(f"{str(doc_path)!r} names arrays_file={name!r}; expected {ARRAYS_FILE!r}")
    arr_path = path / ARRAYS_FILE
    if not arr_path.is_file():
        raise ValueError(f"{str(arr_path)!r} is missing (the model's weights)")
    if _sha256(arr_path) != doc.get("arrays_sha256"):
        raise ValueError(f"{str(arr_path)!r} does not match the checksum in {DOC_FILE} "
                         "(corrupted, truncated or replaced)")
    return doc, read_npz(arr_path, max_arrays=MAX_ARRAYS, max_bytes=MAX_ARRAY_BYTES)


def _config(model) -> dict:
    p = model.get_params(deep=False)
    p.pop("vehicle")
    p["hidden"] = [int(h) for h in p["hidden"]]
    if p["features"] is not None:
        p["features"] = list(p["features"])
    return p


def save_model(model, path: str | os.PathLike, *, option: str = "path") -> None:
    """Write a (fitted or unfitted) :class:`hybridev.HybridModel` to the directory ``path``.

    Each component writes its own state (``to_arrays() -> (json_doc, arrays)``), stored
    under ``components`` and as ``<component>.*`` arrays; ``path`` must be new, empty or
    a folder hybridev wrote (else ``ValueError`` naming ``option``); see
    :func:`write_model_dir`.
    """
    model._check_params()
    doc = {"format": FORMAT_NAME, "format_version": FORMAT_VERSION,
           "estimator": type(model).__name__, "config": _config(model),
           "vehicle": dataclasses.asdict(model._vehicle()), "fitted": model.fitted(),
           "components": {}}
    arrays = {}
    if model.fitted():
        doc["fit_info"] = model.fit_info_
        for name, comp in model.components().items():
            state = comp.to_arrays()  # (doc, arrays), or arrays only (TrainingDomain)
            cdoc, carrays = state if isinstance(state, tuple) else ({}, state)
            doc["components"][name] = cdoc
            arrays.update({f"{name}.{k}": v for k, v in carrays.items()})
    extra_doc, extra_arrays = model._extra_state()
    doc["extra"] = extra_doc
    arrays.update({f"extra.{k}": v for k, v in extra_arrays.items()})
    write_model_dir(path, doc, arrays or None, option=option)


COMPONENTS = ("physics", "learner", "domain", "calibrator", "gate", "planned", "gap_rate")
"""Components of a saved model, in the order they are restored."""


def _legacy_components(doc: dict, arrays: dict[str, np.ndarray]) -> tuple[dict, dict]:
    """A format-1 or -2 document and arrays in the layout of format 3.

    Those formats kept the network and its scalers at the top level and the rest as
    ``extra``: the posterior (``posterior``, ``posterior_*``, ``discrepancy.*``), the
    calibration (``mondrian_cut_km``, ``cv_folds``, ``conformal_*``, ``cv{k}.*``) and the
    domain (``domain.*``); other ``extra`` entries (a subclass's) stay there.
    """
    docs = {c: {} for c in COMPONENTS}
    docs["learner"] = {k: doc[k] for k in ("feature_names", "target_mean", "target_std",
                                           "history") if k in doc}
    extra = dict(doc.get("extra", {}))
    if "posterior" in extra:
        docs["physics"]["posterior"] = extra.pop("posterior")
    for key in ("mondrian_cut_km", "cv_folds"):
        if key in extra:
            docs["calibrator"][key] = extra.pop(key)
    out = {}
    for k, v in arrays.items():
        if not k.startswith("extra."):
            out[f"learner.{k}"] = v
            continue
        name = k[len("extra."):]
        if name.startswith(("posterior_", "discrepancy.")):
            out[f"physics.{name}"] = v
        elif name.startswith("conformal_") or re.match(r"cv[0-9]+\.", name):
            out[f"calibrator.{name}"] = v
        elif name.startswith(("domain.", "planned.", "gap_rate.")):
            out[name] = v
        else:
            out[k] = v
    return {**doc, "components": docs, "extra": extra}, out


def load_model(cls, path: str | os.PathLike):
    """Read a model of class ``cls`` written by :func:`save_model` (format 1, 2 or 3).

    Raises
    ------
    ValueError
        Naming the file and the problem.
    """
    doc, arrays = read_model_dir(path, format_name=FORMAT_NAME, format_version=FORMAT_VERSION)
    where = f"{os.fspath(path)!r}"
    if doc.get("estimator") != cls.__name__:
        raise ValueError(f"{where} holds a {doc.get('estimator')!r}, not a {cls.__name__}")
    arrays = arrays or {}
    if "components" not in doc:  # formats 1 and 2
        doc, arrays = _legacy_components(doc, arrays)
    try:
        model = cls(vehicle=VehicleParams(**doc["vehicle"]), **doc["config"])
        model._check_params()
        if doc["fitted"]:
            if not arrays:
                raise ValueError("the model is marked fitted but has no arrays")
            comps = doc["components"]
            parts = {c: (comps.get(c, {}), {k[len(c) + 1:]: v for k, v in arrays.items()
                                            if k.startswith(c + ".")}) for c in COMPONENTS}
            restore(model, parts, dict(doc["fit_info"]))
        model._set_extra_state(doc.get("extra", {}), {
            k[len("extra."):]: v for k, v in arrays.items() if k.startswith("extra.")})
    except (KeyError, TypeError, ValueError, AttributeError, IndexError, OverflowError,
            RuntimeError) as exc:
        msg = f"missing entry {exc}" if isinstance(exc, KeyError) else str(exc)
        raise ValueError(f"{where} is not a valid saved {cls.__name__}: {msg}") from exc
    from hybridev.learning.sanity import check_model_sanity  # semantic validation (issue 33)
    check_model_sanity(model, path)
    return model
