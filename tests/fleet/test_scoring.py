"""Dask scoring equals pandas scoring, row for row, for the same seed (any partitioning).

Equal to a relative 1e-12: the matrix products behind the physics energies go
through BLAS, which picks its kernel by matrix size, so the last bit of a row
may depend on how many rows share its partition (seen: 2e-16). Everything
random (traces keyed by trip, posterior draws chosen by seed) is identical.
"""

import numpy as np
import pandas as pd
import pytest

from hybridev import make_trips

dd = pytest.importorskip("dask.dataframe")


def _trips(n=150, *, ids=True):
    t = make_trips(n, seed=5).sample(frac=1.0, random_state=1).reset_index(drop=True)
    t.loc[::3, "mode"] = None  # unlabelled trips: posterior-weighted profile mixture
    return t if ids else t.drop(columns="trip_id")


def _same(got: pd.DataFrame, ref: pd.DataFrame) -> None:
    assert list(got.columns) == list(ref.columns)
    got = got.reset_index(drop=True)
    for c in ref.columns:
        if ref[c].dtype.kind in "fiu":
            np.testing.assert_allclose(got[c].to_numpy(), ref[c].to_numpy(), rtol=1e-12,
                                       atol=0.0, err_msg=c)
        else:
            assert got[c].tolist() == ref[c].tolist(), c


@pytest.mark.parametrize("ids", [True, False])
@pytest.mark.parametrize("nparts", [1, 3, 7])
def test_predict_interval_equals_pandas(client, fitted, nparts, ids):
    trips = _trips(ids=ids)
    ref = fitted.predict_interval(trips, 0.8, seed=3)
    lazy = fitted.predict_interval(dd.from_pandas(trips, npartitions=nparts), 0.8, seed=3)
    assert isinstance(lazy, dd.DataFrame)
    _same(lazy.compute(), ref)
    assert list(lazy._meta.columns) == list(ref.columns)


def test_seed_changes_the_intervals(client, fitted):
    trips = dd.from_pandas(_trips(60), npartitions=2)
    a = fitted.predict_interval(trips, 0.8, seed=3).compute()
    b = fitted.predict_interval(trips, 0.8, seed=4).compute()
    assert not np.array_equal(a.energy_kwh_hi, b.energy_kwh_hi)


@pytest.mark.parametrize("nparts", [1, 3, 7])
def test_predict_equals_pandas(client, fitted, nparts):
    trips = _trips(ids=False)
    _same(fitted.predict(dd.from_pandas(trips, npartitions=nparts)).compute(),
          fitted.predict(trips))


def test_partition_scored_in_slices_gives_the_same_rows(fitted, monkeypatch):
    """A partition longer than SCORE_CHUNK_ROWS is scored slice by slice, bit for bit."""
    from hybridev.fleet import scoring

    trips = _trips(ids=True)
    whole = scoring._score(trips, fitted, "predict_interval", {"level": 0.8, "seed": 3})
    monkeypatch.setattr(scoring, "SCORE_CHUNK_ROWS", 16)  # 150 rows: ten slices
    sliced = scoring._score(trips, fitted, "predict_interval", {"level": 0.8, "seed": 3})
    pd.testing.assert_frame_equal(sliced, whole, check_exact=True)
    assert sliced.equals(whole)


def test_model_is_one_task_of_the_graph(fitted):
    """Every partition task depends on one key holding the model: shipped once."""
    lazy = fitted.predict_interval(dd.from_pandas(_trips(60), npartitions=5), 0.8)
    graph = dict(lazy.__dask_graph__())
    model_keys = [k for k in graph
                  if str(k[0] if isinstance(k, tuple) else k).startswith("hybridev-model-")]
    assert len(model_keys) == 1
    users = [k for k, v in graph.items() if model_keys[0] in getattr(v, "dependencies", ())]
    assert len(users) == 5


def test_bad_level_fails_at_once(fitted):
    with pytest.raises(ValueError, match="level"):
        fitted.predict_interval(dd.from_pandas(_trips(10), npartitions=2), 1.5)


def test_bad_row_names_the_field_at_compute(client, fitted):
    trips = _trips(20)
    trips.loc[4, "soc_initial"] = 1.7
    lazy = fitted.predict_interval(dd.from_pandas(trips, npartitions=2), 0.8)
    with pytest.raises(ValueError, match="soc_initial"):
        lazy.compute()


def _timeseries(trip_ids):
    rows = []
    for i, k in enumerate(trip_ids):
        t = np.arange(0.0, 600.0 + 60 * i, 1.0)
        v = 50.0 + 20.0 * np.sin(t / (30.0 + i))
        rows.append(pd.DataFrame({"trip_id": k, "t_s": t, "speed_kmh": v}))
    return pd.concat(rows, ignore_index=True)


@pytest.mark.parametrize("lazy_ts", [False, True])
def test_logged_traces_pandas_or_dask(client, fitted, lazy_ts):
    trips = _trips(40)
    ts = _timeseries(trips.trip_id.to_numpy()[:15])
    ref = fitted.predict_interval(trips, 0.8, seed=1, timeseries=ts)
    tsd = dd.from_pandas(ts, npartitions=4) if lazy_ts else ts
    got = fitted.predict_interval(dd.from_pandas(trips, npartitions=3), 0.8, seed=1,
                                  timeseries=tsd).compute()
    got = got.set_index("trip_id").loc[ref.trip_id].reset_index()  # shuffled by trip_id
    _same(got[ref.columns], ref)


def test_coarse_sampling_warns_with_one_text_for_every_partition(fitted):
    """A coarsely sampled dask time series: each partition checks its own traces, and
    says so in one text (shown once), not with each partition's own median. The
    partition function is called directly, as a worker would (no scheduler needed)."""
    import warnings

    from hybridev.core.errors import DataWarning
    from hybridev.fleet.scoring import _score

    trips = _trips(40)
    ids = trips.trip_id.to_numpy()[:10]
    texts = set()
    for step, part in ((3.0, ids[:5]), (5.0, ids[5:])):  # two partitions, two medians
        ts = _timeseries(part)
        ts = ts[ts["t_s"] % step == 0]
        with warnings.catch_warnings(record=True) as rec:
            warnings.simplefilter("always")
            _score(trips[trips.trip_id.isin(part)], fitted, "predict_interval",
                   {"level": 0.8, "seed": 1}, ts)
        texts |= {str(w.message) for w in rec if issubclass(w.category, DataWarning)}
    assert len(texts) == 1
    assert next(iter(texts)).startswith("timeseries: in some partitions the samples are more "
                                        "than 2 s apart (median): between samples")


def test_start_times_need_a_parked_min_column_on_dask(client, fitted):
    """Parking time needs the previous trip, which may sit in another partition."""
    trips = _trips(12).assign(start_time=pd.date_range("2024-01-05 07:00", periods=12,
                                                      freq="40min"))
    with pytest.raises(ValueError, match="parked_min"):
        fitted.predict(dd.from_pandas(trips, npartitions=2))
    from hybridev import parked_minutes

    ready = trips.assign(parked_min=parked_minutes(trips))
    _same(fitted.predict(dd.from_pandas(ready, npartitions=3)).compute(),
          fitted.predict(trips))  # pandas derives the same column itself
