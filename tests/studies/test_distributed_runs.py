"""Many-run optimisation jobs on a real Dask LocalCluster (TCP scheduler, 2 worker processes): the
Pareto weights and the starts of a multi-start give the same files as run one after the other here."""
import csv
import json
import tomllib

from aquarom_fenics.cli import main
from aquarom_fenics.io.scene import scene_from_dict


CO_SMALL = {"mesh": {"level": 1}, "solver": {"duration": 0.2}, "shapes": {"z_tail": {"bounds": [-0.5, 0.5]}},
            "cooptimization": {"enabled": True, "weights": [0.3, 0.9]}, "optimizer": {"max_iterations": 2}}


def test_pareto_through_dask_equals_the_weights_run_here(tmp_path, monkeypatch, dask_cluster):
    """One weight per task on a LocalCluster (fresh caches): the same pareto.csv, every float alike."""
    scene_file = tmp_path / "co-small.toml"
    scene_file.write_text(scene_from_dict(CO_SMALL, source="<test>").to_toml())
    assert tomllib.loads(scene_file.read_text())["cooptimization"]["weights"] == [0.3, 0.9]
    tables = {}
    for backend, options in (("here", []), ("dask", ["--scheduler", dask_cluster.scheduler_address])):
        monkeypatch.setenv("AQUAROM_CACHE", str(tmp_path / f"cache-{backend}"))
        assert main(["pareto", str(scene_file), "--out", str(tmp_path / backend), *options]) == 0
        tables[backend] = (tmp_path / backend / "pareto.csv").read_text()
    assert tables["dask"] == tables["here"]
    assert len(tables["here"].splitlines()) == 3


MULTISTART = {"mesh": {"level": 1}, "solver": {"duration": 0.2},
              "shapes": {"z_tail": {"bounds": [-0.5, 0.5]}, "y_thin": {"bounds": [0.0, 0.1]}},
              "optimizer": {"max_iterations": 2, "starts": 2}}


def test_multistart_through_dask_equals_the_starts_run_here(tmp_path, monkeypatch, dask_cluster):
    scene_file = tmp_path / "multistart.toml"
    scene_file.write_text(scene_from_dict(MULTISTART, source="<test>").to_toml())
    summaries = {}
    for backend, options in (("here", []), ("dask", ["--scheduler", dask_cluster.scheduler_address])):
        monkeypatch.setenv("AQUAROM_CACHE", str(tmp_path / f"cache-{backend}"))
        assert main(["optimize", str(scene_file), "--out", str(tmp_path / backend), *options]) == 0
        summaries[backend] = json.loads((tmp_path / backend / "summary.json").read_text())
    here, dask = summaries["here"]["multistart"], summaries["dask"]["multistart"]
    assert len(here["local_optima"]) == 2 and dask == here
    assert summaries["dask"]["optimum"] == summaries["here"]["optimum"]
    histories = {backend: history(tmp_path / backend / "start_2" / "history.csv") for backend in summaries}
    assert histories["dask"] == histories["here"] and len(histories["here"]) == 3


def history(path) -> list[dict]:
    """The rows of a history.csv without its wall-time columns."""
    with open(path, newline="") as stream:
        return [{key: value for key, value in row.items() if "time" not in key} for row in csv.DictReader(stream)]
