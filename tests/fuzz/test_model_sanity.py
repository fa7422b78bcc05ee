"""Models that pass every checksum but make no sense are refused at load
(:mod:`hybridev.learning.sanity`); any model file that loads predicts finite values.

Files are edited as a hand-edit or a buggy writer would, then re-signed (the
array checksum in ``model.json`` and the manifest recomputed), so only the
semantic check stands between them and a NaN.
"""

import io
import json
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hybridev import HybridModel
from hybridev.core.outputs import MANIFEST_FILE, sha256_file
from hybridev.learning.persist import ARRAYS_FILE, DOC_FILE


def _arrays(path):
    with np.load(path / ARRAYS_FILE) as z:
        return {k: z[k] for k in z.files}


def _write(path, doc=None, arrays=None):
    """Rewrite model.json and/or arrays.npz and re-sign both checksums."""
    doc = json.loads((path / DOC_FILE).read_text()) if doc is None else doc
    if arrays is not None:
        buf = io.BytesIO()
        np.savez_compressed(buf, **arrays)
        (path / ARRAYS_FILE).write_bytes(buf.getvalue())
    doc["arrays_sha256"] = sha256_file(path / ARRAYS_FILE)
    (path / DOC_FILE).write_text(json.dumps(doc))
    man = json.loads((path / MANIFEST_FILE).read_text())
    for name in man["files"]:
        man["files"][name] = sha256_file(path / name)
    (path / MANIFEST_FILE).write_text(json.dumps(man))


def _copy(fuzz_files, tmp_path, name="model"):
    dst = tmp_path / f"m{len(list(tmp_path.iterdir()))}"
    shutil.copytree(fuzz_files / name, dst)
    return dst


def _doc(path):
    return json.loads((path / DOC_FILE).read_text())


def _refused(path, *words):
    with pytest.raises(ValueError) as info:
        HybridModel.load(path)
    msg = str(info.value)
    assert str(path) in msg, msg
    for w in words:
        assert w in msg, msg
    return msg


def test_issue_cases_are_refused_naming_file_and_field(fuzz_files, tmp_path):
    # target_std = 1e300 (NaN in every interval)
    p = _copy(fuzz_files, tmp_path)
    d = _doc(p)
    d["components"]["learner"]["target_std"] = 1e300
    _write(p, d)
    _refused(p, "learner.target_std")
    # NaN training-domain bounds (NaN in every prediction)
    p = _copy(fuzz_files, tmp_path)
    a = _arrays(p)
    a["domain.feature_lo"] = np.full_like(a["domain.feature_lo"], np.nan)
    _write(p, arrays=a)
    _refused(p, "domain.feature_lo")
    # posterior draws with a negative drag area, an efficiency of 5.0
    doc = _doc(fuzz_files / "model")
    names = doc["components"]["physics"]["posterior"]["param_names"]
    for name, value in (("drag_area_m2", -0.2), ("drivetrain_efficiency", 5.0)):
        if name not in names:
            continue
        p = _copy(fuzz_files, tmp_path)
        a = _arrays(p)
        a["physics.posterior_samples"][3, names.index(name)] = value
        _write(p, arrays=a)
        _refused(p, "posterior_samples", name)
    # network weights of 1e30
    p = _copy(fuzz_files, tmp_path)
    a = _arrays(p)
    a["learner.net.w0"] = a["learner.net.w0"] * np.float32(1e30)
    _write(p, arrays=a)
    _refused(p, "net.w0")
    # a vehicle of 99,999 kg: not the vehicle its physics posterior was calibrated on
    p = _copy(fuzz_files, tmp_path)
    d = _doc(p)
    d["vehicle"]["mass_kg"] = 99999.0
    _write(p, d)
    _refused(p, "vehicle.mass_kg")
    # ... and in a model without a posterior, physics beyond any battery vehicle
    p = _copy(fuzz_files, tmp_path, "paper")
    d = _doc(p)
    d["vehicle"]["mass_kg"] = 99999.0
    _write(p, d)
    _refused(p, "kWh/km")


def test_sound_models_still_load(fuzz_files):
    for name in ("model", "paper"):
        HybridModel.load(fuzz_files / name)


_JSON_FIELDS = ("target_mean", "target_std")
_VALUES = st.sampled_from([np.nan, np.inf, -np.inf, 1e30, -1e30, 1e6, -1.0, 0.0, 1e-30,
                           5.0, -0.2, 0.5, 2.0])


@st.composite
def _edit(draw, keys):
    if draw(st.booleans()):
        return ("json", draw(st.sampled_from(_JSON_FIELDS)), draw(_VALUES))
    key = draw(st.sampled_from(keys))
    how = draw(st.sampled_from(["set", "scale"]))
    return ("array", key, how, draw(_VALUES), draw(st.integers(0, 10_000)))


_TRIPS = st.fixed_dictionaries({
    "distance_km": st.floats(0.5, 300.0), "avg_speed_kmh": st.floats(5.0, 130.0),
    "temperature_c": st.floats(-25.0, 40.0), "soc_initial": st.floats(0.3, 1.0),
    "mode": st.sampled_from(["eco", "normal", "aggressive", None]),
    "hour": st.floats(0.0, 23.5)})


@pytest.mark.slow
def test_any_model_that_loads_predicts_finite_values(fuzz_files, tmp_path_factory):
    keys = sorted(k for k in _arrays(fuzz_files / "model")
                  if not k.endswith(("train_loss", "val_loss")))
    base = tmp_path_factory.mktemp("sanity")
    counter = iter(range(10**6))

    @settings(max_examples=40, deadline=None, derandomize=True,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
    @given(edits=st.lists(_edit(keys), min_size=1, max_size=3),
           trips=st.lists(_TRIPS, min_size=1, max_size=4))
    def prop(edits, trips):
        p = base / f"m{next(counter)}"
        shutil.copytree(fuzz_files / "model", p)
        doc, arrays = _doc(p), _arrays(p)
        for e in edits:
            if e[0] == "json":
                doc["components"]["learner"][e[1]] = (float(e[2]) if np.isfinite(e[2])
                                                      else e[2])
            else:
                _, key, how, value, at = e
                a = arrays[key]
                if a.dtype == bool or a.size == 0:
                    continue
                a = a.astype(a.dtype, copy=True)
                if how == "set":
                    a.ravel()[at % a.size] = value if np.issubdtype(a.dtype, np.floating) \
                        else int(np.clip(np.nan_to_num(value), -2**31, 2**31 - 1))
                elif np.issubdtype(a.dtype, np.floating):
                    a = (a * value).astype(a.dtype)
                arrays[key] = a
        (p / DOC_FILE).write_text(json.dumps(doc))  # NaN/inf written as JSON extensions
        _write(p, json.loads((p / DOC_FILE).read_text()), arrays)
        try:
            m = HybridModel.load(p)
        except ValueError as exc:
            assert str(p) in str(exc)
            return
        t = pd.DataFrame(trips).assign(trip_id=range(len(trips)))
        out = m.predict_interval(t, 0.8, seed=0)
        vals = out[["energy_kwh_pred", "energy_kwh_lo", "energy_kwh_hi",
                    "soc_final_pred"]].to_numpy(float)
        assert np.all(np.isfinite(vals)), (edits, trips, vals)

    prop()


def test_a_format_1_model_without_manifest_is_checked_too(tmp_path):
    """A model file of format 1 (no manifest: model.json carries no checksum) written by
    the hybridev of that format (tests/learning/fixtures), then hand-edited."""
    p = tmp_path / "format1"
    shutil.copytree(Path(__file__).parents[1] / "learning" / "fixtures" / "format1_split", p)
    assert not (p / MANIFEST_FILE).exists()
    d = _doc(p)
    assert d["format_version"] == 1
    d["target_std"] = 1e300
    (p / DOC_FILE).write_text(json.dumps(d))
    _refused(p, "target_std")
    assert zipfile.is_zipfile(p / ARRAYS_FILE)
