"""Shared fixtures: the coarsest mesh level and short horizons keep the suite fast."""
import os

import pytest

from aquarom_fenics.io.scene import scene_from_dict

os.environ.setdefault("OMPI_ALLOW_RUN_AS_ROOT", "1")
os.environ.setdefault("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")


@pytest.fixture(autouse=True, scope="session")
def isolated_cache(tmp_path_factory):
    """FOM-check results are cached per test session, never in the repository."""
    os.environ["AQUAROM_CACHE"] = str(tmp_path_factory.mktemp("cache"))



SHORT_SCENE = """
[mesh]
level = 1
[solver]
duration = {duration}
[shapes]
z_tail = {{ bounds = [-0.2, 0.2] }}
y_thin = {{ bounds = [-0.1, 0.1] }}
{extra}
"""
"""A scene file on level 1 with two shapes: format with ``duration`` [s] and ``extra`` TOML."""


def coarse_scene(**sections):
    """A scene on mesh level 1; keyword arguments are TOML tables, e.g. solver={"duration": 0.2}."""
    data = {"mesh": {"level": 1}}
    for name, table in sections.items():
        data[name] = {**data.get(name, {}), **table}
    return scene_from_dict(data, source="<test>")


@pytest.fixture
def make_scene():
    return coarse_scene


@pytest.fixture(scope="session")
def dask_cluster():
    """A real Dask distributed cluster on this machine: TCP scheduler, 2 worker processes of one
    thread each (made once, for the tests that ask for it)."""
    import logging

    from distributed import LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, protocol="tcp://", dashboard_address=None,
                      silence_logs=logging.ERROR) as cluster:
        yield cluster
