"""Model directories on disk: one JSON document plus one ``.npz`` of arrays, no pickle.

:func:`save_model` / :func:`load_model` implement ``HybridModel.save`` and
``HybridModel.load``. Layout of a model directory (format version 2)::

    model.json              format name and version, hybridev version, configuration,
                            vehicle, feature names, training summary, and the name and
                            SHA-256 of the array file
    arrays.npz              numpy arrays (network weights, scalers, loss curves);
                            absent when nothing was fitted
    _hybridev-manifest.json  the marker of a folder written by hybridev
                            (:mod:`hybridev.core.outputs`): ``kind: "model_dir"``,
                            format name and version, and the SHA-256 of every file

Extensions of the model (a physics posterior, a conformal calibration) keep
their state through ``model._extra_state() -> (json_dict, arrays)`` and
``model._set_extra_state(json_dict, arrays)``, stored under ``"extra"`` and as
``extra.*`` arrays.

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
wrong names or shapes. Models of format version 1 (no manifest; only the
array file is checksummed) still load.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
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
from hybridev.learning.nn import EnsembleMLP, n_parameters
from hybridev.physics.params import VehicleParams

__all__ = ["ARRAYS_FILE", "DOC_FILE", "FORMAT_NAME", "FORMAT_VERSION", "MAX_ARRAYS",
           "MAX_ARRAY_BYTES", "check_model_path", "load_model", "read_model_dir", "save_model", "write_model_dir"]

DOC_FILE = "model.json"
ARRAYS_FILE = "arrays.npz"
FORMAT_NAME = "hybridev.learning.model"
"""Format name of a saved :class:`hybridev.HybridModel` (or subclass)."""
FORMAT_VERSION = 2
"""Version of that format (2: with a manifest of SHA-256 sums); version 1 is still read,
other versions are refused."""
READ_VERSIONS = (1, 2)
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
    ValueError: --out=... is an existing folder with files hybridev did not write there ...
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

    ``format_version`` is the current version; version 1 (no manifest) is
    read too when ``format_version`` is 2.

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

    ``path`` must be new, empty or a folder hybridev wrote (else ``ValueError``
    naming ``option``); see :func:`write_model_dir`.
    """
    model._check_params()
    fitted = hasattr(model, "net_")
    doc = {"format": FORMAT_NAME, "format_version": FORMAT_VERSION,
           "estimator": type(model).__name__, "config": _config(model),
           "vehicle": dataclasses.asdict(model._vehicle()), "fitted": fitted}
    arrays = None
    if fitted:
        h = model.history_
        doc.update(feature_names=list(model.feature_names_),
                   target_mean=model.target_mean_, target_std=model.target_std_,
                   history={"best_epoch": np.asarray(h["best_epoch"]).tolist(),
                            "stopped_epoch": np.asarray(h["stopped_epoch"]).tolist(),
                            "n_epochs": int(h["n_epochs"])},
                   fit_info=model.fit_info_)
        arrays = {f"net.{k}": v for k, v in model.net_.to_arrays().items()}
        arrays.update(feature_mean=model.feature_mean_, feature_std=model.feature_std_,
                      train_loss=h["train_loss"], val_loss=h["val_loss"])
    extra_doc, extra_arrays = model._extra_state()
    doc["extra"] = extra_doc
    if extra_arrays:
        arrays = {**(arrays or {}), **{f"extra.{k}": v for k, v in extra_arrays.items()}}
    write_model_dir(path, doc, arrays, option=option)


def _restore(model, doc: dict, arrays: dict[str, np.ndarray]) -> None:
    """Set the learned attributes of ``model`` from a saved document and arrays."""
    names = tuple(doc["feature_names"])
    if names != model._feature_names():
        raise ValueError(f"feature_names={list(names)!r} do not match the model's features "
                         f"{list(model._feature_names())!r}")
    stored = sum(int(v.size) for k, v in arrays.items() if k.startswith("net."))
    need = int(model.n_members) * n_parameters(len(names), model.hidden,
                                               heteroscedastic=bool(model.heteroscedastic))
    if need != stored:  # checked before the network is allocated
        raise ValueError(f"the configuration (n_members={model.n_members}, hidden="
                         f"{list(model.hidden)}) needs {need} network weights, but "
                         f"{ARRAYS_FILE} stores {stored}")
    net = EnsembleMLP(len(names), model.hidden, n_members=model.n_members,
                      dropout=model.dropout, heteroscedastic=model.heteroscedastic)
    net.load_arrays({k[4:]: v for k, v in arrays.items() if k.startswith("net.")},
                    what="network")
    net.eval()
    for key in ("feature_mean", "feature_std"):
        a = arrays.get(key)
        if a is None or a.shape != (len(names),) or not np.all(np.isfinite(a)):
            raise ValueError(f"array {key!r} must be {len(names)} finite values")
    if np.any(arrays["feature_std"] <= 0):
        raise ValueError("array 'feature_std' must be positive")
    target_mean, target_std = float(doc["target_mean"]), float(doc["target_std"])
    if not (math.isfinite(target_mean) and math.isfinite(target_std) and target_std > 0):
        raise ValueError(f"target_mean={target_mean!r}, target_std={target_std!r} must be "
                         "finite, target_std > 0")
    h = doc["history"]
    model.history_ = {"train_loss": arrays["train_loss"], "val_loss": arrays["val_loss"],
                      "best_epoch": np.asarray(h["best_epoch"]),
                      "stopped_epoch": np.asarray(h["stopped_epoch"]),
                      "n_epochs": int(h["n_epochs"])}
    model.feature_names_, model.n_features_in_ = names, len(names)
    model.feature_mean_ = arrays["feature_mean"].astype(float)
    model.feature_std_ = arrays["feature_std"].astype(float)
    model.target_mean_, model.target_std_ = target_mean, target_std
    model.fit_info_ = dict(doc["fit_info"])
    model.n_parameters_ = net.n_parameters_per_member
    model.net_ = net


def load_model(cls, path: str | os.PathLike):
    """Read a model of class ``cls`` written by :func:`save_model`.

    Raises
    ------
    ValueError
        Naming the file and the problem.
    """
    doc, arrays = read_model_dir(path, format_name=FORMAT_NAME, format_version=FORMAT_VERSION)
    where = f"{os.fspath(path)!r}"
    if doc.get("estimator") != cls.__name__:
        raise ValueError(f"{where} holds a {doc.get('estimator')!r}, not a {cls.__name__}")
    try:
        model = cls(vehicle=VehicleParams(**doc["vehicle"]), **doc["config"])
        model._check_params()
        if doc["fitted"]:
            if arrays is None:
                raise ValueError("the model is marked fitted but has no arrays")
            _restore(model, doc, arrays)
        model._set_extra_state(doc.get("extra", {}), {
            k[len("extra."):]: v for k, v in (arrays or {}).items() if k.startswith("extra.")})
    except (KeyError, TypeError, ValueError, AttributeError, IndexError, OverflowError,
            RuntimeError) as exc:
        msg = f"missing entry {exc}" if isinstance(exc, KeyError) else str(exc)
        raise ValueError(f"{where} is not a valid saved {cls.__name__}: {msg}") from exc
    from hybridev.learning.sanity import check_model_sanity  # semantic validation (issue 33)
    check_model_sanity(model, path)
    return model
