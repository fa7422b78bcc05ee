"""Model directories on disk: one JSON document plus one ``.npz`` of arrays, no pickle.

:func:`save_model` / :func:`load_model` implement ``HybridModel.save`` and
``HybridModel.load``. Layout of a model directory::

    model.json     format name and version, hybridev version, configuration,
                   vehicle, feature names, training summary, and the name and
                   SHA-256 of the array file
    arrays.npz     numpy arrays (network weights, scalers, loss curves);
                   absent when nothing was fitted

Extensions of the model (a physics posterior, a conformal calibration) keep
their state through ``model._extra_state() -> (json_dict, arrays)`` and
``model._set_extra_state(json_dict, arrays)``, stored under ``"extra"`` and as
``extra.*`` arrays.

Writing is atomic (:func:`hybridev.core.fileio.atomic_dir`): a failed save leaves any
previous directory untouched. Reading checks everything it can and raises a
``ValueError`` naming the file and the problem: missing or unreadable files,
invalid JSON, another format or format version, a model written by another
major version of hybridev, a checksum mismatch (corruption, truncation), and
(through :func:`read_model_dir`'s callers) wrong names or shapes.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import zipfile
from pathlib import Path

import numpy as np

from hybridev.core.fileio import atomic_dir
from hybridev.learning.nn import EnsembleMLP
from hybridev.physics.params import VehicleParams

__all__ = ["ARRAYS_FILE", "DOC_FILE", "FORMAT_NAME", "FORMAT_VERSION", "load_model",
           "read_model_dir", "save_model", "write_model_dir"]

DOC_FILE = "model.json"
ARRAYS_FILE = "arrays.npz"
FORMAT_NAME = "hybridev.learning.model"
"""Format name of a saved :class:`hybridev.HybridModel` (or subclass)."""
FORMAT_VERSION = 1
"""Version of that format; files of any other version are refused."""


def _major(version: str) -> int:
    return int(str(version).split(".")[0])


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def write_model_dir(path: str | os.PathLike, doc: dict, arrays: dict[str, np.ndarray] | None
                    ) -> None:
    """Write ``doc`` (JSON-serialisable) and ``arrays`` to the directory ``path``, atomically.

    ``doc`` gains ``hybridev_version``, ``arrays_file`` and ``arrays_sha256``.

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
    with atomic_dir(path) as tmp:
        if arrays is not None:
            with open(tmp / ARRAYS_FILE, "wb") as fh:
                np.savez_compressed(fh, **arrays)
            doc["arrays_file"] = ARRAYS_FILE
            doc["arrays_sha256"] = _sha256(tmp / ARRAYS_FILE)
        else:
            doc["arrays_file"] = None
        (tmp / DOC_FILE).write_text(json.dumps(doc, indent=1, allow_nan=False) + "\n",
                                    encoding="utf-8")


def read_model_dir(path: str | os.PathLike, *, format_name: str, format_version: int
                   ) -> tuple[dict, dict[str, np.ndarray] | None]:
    """Read a directory written by :func:`write_model_dir`, checking format and integrity.

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
    try:
        doc = json.loads(doc_path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"{str(doc_path)!r} is not valid JSON (corrupted or truncated?): "
                         f"{exc}") from exc
    if not isinstance(doc, dict):
        raise ValueError(f"{str(doc_path)!r} must hold a JSON object; got {type(doc).__name__}")
    if doc.get("format") != format_name:
        raise ValueError(f"{str(doc_path)!r} has format={doc.get('format')!r}; "
                         f"expected {format_name!r}")
    if doc.get("format_version") != format_version:
        raise ValueError(f"{str(doc_path)!r} has format_version={doc.get('format_version')!r}; "
                         f"this hybridev reads format_version {format_version} only")
    from hybridev import __version__

    saved = doc.get("hybridev_version")
    try:
        other_major = _major(saved) != _major(__version__)
    except (TypeError, ValueError):
        raise ValueError(f"{str(doc_path)!r} has an invalid hybridev_version={saved!r}") from None
    if other_major:
        raise ValueError(f"{str(doc_path)!r} was written by hybridev {saved}; this is hybridev "
                         f"{__version__} (another major version): re-fit the model")
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
    try:
        with np.load(arr_path, allow_pickle=False) as npz:
            arrays = {k: npz[k] for k in npz.files}
    except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile) as exc:
        raise ValueError(f"{str(arr_path)!r} could not be read as a .npz array file: "
                         f"{exc}") from exc
    return doc, arrays


def _config(model) -> dict:
    p = model.get_params(deep=False)
    p.pop("vehicle")
    p["hidden"] = [int(h) for h in p["hidden"]]
    if p["features"] is not None:
        p["features"] = list(p["features"])
    return p


def save_model(model, path: str | os.PathLike) -> None:
    """Write a (fitted or unfitted) :class:`hybridev.HybridModel` to the directory ``path``."""
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
    write_model_dir(path, doc, arrays)


def _restore(model, doc: dict, arrays: dict[str, np.ndarray]) -> None:
    """Set the learned attributes of ``model`` from a saved document and arrays."""
    names = tuple(doc["feature_names"])
    if names != model._feature_names():
        raise ValueError(f"feature_names={list(names)!r} do not match the model's features "
                         f"{list(model._feature_names())!r}")
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
    except (KeyError, TypeError, ValueError) as exc:
        msg = f"missing entry {exc}" if isinstance(exc, KeyError) else str(exc)
        raise ValueError(f"{where} is not a valid saved {cls.__name__}: {msg}") from exc
    return model
