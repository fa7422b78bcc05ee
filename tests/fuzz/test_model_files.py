"""Saved model files: truncated, bit-flipped and crafted files never load as another model."""

import io
import json
import shutil
import tracemalloc
import zipfile

import numpy as np
import pandas as pd
import pytest

from hybridev import HybridModel
from hybridev.core.outputs import MANIFEST_FILE, sha256_file
from hybridev.learning.persist import ARRAYS_FILE, DOC_FILE


def _predict(model, trips):
    out = model.predict_interval(trips, 0.8, seed=0)
    return out[["energy_kwh_pred", "energy_kwh_lo", "energy_kwh_hi"]].to_numpy()


def _resign(path):
    man = json.loads((path / MANIFEST_FILE).read_text())
    for name in man["files"]:
        man["files"][name] = sha256_file(path / name)
    (path / MANIFEST_FILE).write_text(json.dumps(man))


def flip_sweep(src, dst_root, trips, n_flips, seed):
    """Flip one bit at a time; return counts of (refused, loaded-identical, loaded-different)."""
    ref = _predict(HybridModel.load(src), trips)
    rng = np.random.default_rng(seed)
    files = sorted(p.name for p in src.iterdir())
    counts = {"refused": 0, "same": 0, "different": 0}
    for k in range(n_flips):
        dst = dst_root / f"flip{k}"
        shutil.copytree(src, dst)
        name = files[k % len(files)]  # every file gets its share of flips
        data = bytearray((dst / name).read_bytes())
        i = int(rng.integers(len(data)))
        data[i] ^= 1 << int(rng.integers(8))
        (dst / name).write_bytes(bytes(data))
        try:
            m = HybridModel.load(dst)
        except ValueError as exc:
            assert str(dst) in str(exc)  # the message names the file or folder
            counts["refused"] += 1
        else:
            same = np.array_equal(_predict(m, trips), ref)
            counts["same" if same else "different"] += 1
        shutil.rmtree(dst)
    return counts


def test_bit_flips_never_load_a_different_model(fuzz_files, tmp_path):
    trips = pd.read_csv(fuzz_files / "trips.csv").head(20)
    counts = flip_sweep(fuzz_files / "model", tmp_path, trips, n_flips=24, seed=1)
    assert counts["different"] == 0, counts
    assert counts["refused"] >= 20, counts


@pytest.mark.slow
def test_bit_flip_sweep_200(fuzz_files, tmp_path):
    """The issue's target: 200 flips over a saved default-configuration model."""
    trips = pd.read_csv(fuzz_files / "trips.csv").head(20)
    counts = flip_sweep(fuzz_files / "model", tmp_path, trips, n_flips=200, seed=2)
    print("bit-flip sweep:", counts)
    assert counts["different"] == 0, counts


@pytest.mark.parametrize("name", [DOC_FILE, ARRAYS_FILE, MANIFEST_FILE])
@pytest.mark.parametrize("keep", [0, 1, 100, 0.5])
def test_truncated_files_are_refused(fuzz_files, tmp_path, name, keep):
    dst = tmp_path / "m"
    shutil.copytree(fuzz_files / "model", dst)
    data = (dst / name).read_bytes()
    n = int(keep * len(data)) if isinstance(keep, float) else keep
    (dst / name).write_bytes(data[:n])
    with pytest.raises(ValueError, match=str(dst)):
        HybridModel.load(dst)


def _crafted_npz(shape, dtype="<f4", payload=b"\0" * 64, member="net.w0.npy"):
    header = {"descr": dtype, "fortran_order": False, "shape": shape}
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(buf, header)
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as zf:
        zf.writestr(member, buf.getvalue() + payload)
    return out.getvalue()


@pytest.mark.parametrize("blob, match", [
    (_crafted_npz((600_000_000,), payload=b"\0" * 2_000_000), "claims shape"),
    (_crafted_npz((10,), dtype="|O"), "only numeric arrays"),
    (_crafted_npz((4,), member="evil.txt"), "not a .npy array"),
    (b"PK\x03\x04 not a zip at all", "could not be read"),
])
def test_crafted_arrays_are_refused_before_allocating(fuzz_files, tmp_path, blob, match):
    dst = tmp_path / "m"
    shutil.copytree(fuzz_files / "model", dst)
    (dst / ARRAYS_FILE).write_bytes(blob)
    doc = json.loads((dst / DOC_FILE).read_text())
    doc["arrays_sha256"] = sha256_file(dst / ARRAYS_FILE)
    (dst / DOC_FILE).write_text(json.dumps(doc))
    _resign(dst)  # a crafted folder passes the checksums; the caps must still hold
    tracemalloc.start()
    try:
        with pytest.raises(ValueError, match=match):
            HybridModel.load(dst)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 100e6, peak  # far below the 2.4 GB the header claims


def test_crafted_config_cannot_allocate_a_huge_network(fuzz_files, tmp_path):
    dst = tmp_path / "m"
    shutil.copytree(fuzz_files / "model", dst)
    doc = json.loads((dst / DOC_FILE).read_text())
    doc["config"]["hidden"] = [4096] * 200
    doc["config"]["n_members"] = 100
    (dst / DOC_FILE).write_text(json.dumps(doc))
    _resign(dst)
    with pytest.raises(ValueError, match=r"needs [0-9]+ network weights"):
        HybridModel.load(dst)


def test_format_1_models_still_load(fuzz_files, tmp_path):
    """A model saved before the manifest (format_version 1) loads and predicts the same."""
    dst = tmp_path / "old"
    shutil.copytree(fuzz_files / "model", dst)
    (dst / MANIFEST_FILE).unlink()
    doc = json.loads((dst / DOC_FILE).read_text())
    doc["format_version"] = 1
    (dst / DOC_FILE).write_text(json.dumps(doc))
    trips = pd.read_csv(fuzz_files / "trips.csv").head(5)
    np.testing.assert_array_equal(_predict(HybridModel.load(dst), trips),
                                  _predict(HybridModel.load(fuzz_files / "model"), trips))
    # and a new save over it is allowed (it is a hybridev model folder)
    HybridModel.load(dst).save(dst)
    assert (dst / MANIFEST_FILE).is_file()


def test_save_never_replaces_a_user_folder_or_file(fuzz_files, tmp_path):
    m = HybridModel.load(fuzz_files / "paper")
    user = tmp_path / "data"
    user.mkdir()
    (user / "trips.csv").write_text("mine\n")
    with pytest.raises(ValueError, match=r"path=.*did not write there"):
        m.save(user)
    with pytest.raises(ValueError, match="never replaces a file with a folder"):
        m.save(user / "trips.csv")
    assert (user / "trips.csv").read_text() == "mine\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["data"]
