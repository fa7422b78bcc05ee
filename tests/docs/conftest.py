"""The warm ``hybridev`` server shared by the docs tests of one process (see ``warm_cli.py``)."""

import os
from pathlib import Path

import pytest
from warm_cli import WarmCli

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def warm_cli(tmp_path_factory):
    env = dict(os.environ, MPLBACKEND="Agg",
               PYTHONPATH=f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}")
    cli = WarmCli(tmp_path_factory.mktemp("warm-cli"), env)
    yield cli
    cli.close()
