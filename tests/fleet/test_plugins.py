"""The entry points from the lower layers into the fleet layer."""

import subprocess
import sys

import pandas as pd
import pytest

from hybridev.core.plugins import ENTRY_POINTS, entry_point, lazy_backend

dd = pytest.importorskip("dask.dataframe")


@pytest.mark.parametrize("name", sorted(ENTRY_POINTS))
def test_entry_points_resolve_into_the_fleet_layer(name):
    assert ENTRY_POINTS[name].startswith("hybridev.fleet.")
    assert callable(entry_point(name))


def test_lazy_backend_by_type_module():
    assert lazy_backend(pd.DataFrame({"a": [1]})) is None
    assert lazy_backend(dd.from_pandas(pd.DataFrame({"a": [1]}), npartitions=1)) == "dask"


def test_import_hybridev_pandas_predict_and_fleet_import_never_import_dask():
    code = ("import sys, warnings, hybridev\n"
            "warnings.simplefilter('ignore')\n"
            "hybridev.HybridModel(n_steps=100).predict(hybridev.make_trips(3))\n"
            "import hybridev.fleet\n"
            "print(sorted({k.split('.')[0] for k in sys.modules} & {'dask', 'distributed'}))")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert res.stdout.strip() == "[]"
