"""Shared fixtures: the coarsest mesh level and short horizons keep the suite fast.

`make test` runs the files on two pytest-xdist workers (``--dist loadfile``: a file stays on one
worker, so its module-scoped meshes, FOM runs and PROMs are built once). Each worker has its own
session, hence its own result cache; the tests marked ``mpi`` take turns (:func:`one_mpirun_at_a_time`).
"""
import faulthandler
import fcntl
import os
import shutil
import signal
import tempfile
import threading
import time
from pathlib import Path

# One BLAS thread per process, set before numpy loads OpenBLAS: the xdist workers (and the CLI
# runs they start) already use both cores, and OpenBLAS threads waiting for a core spin in sched_yield.
for _variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ.setdefault(_variable, "1")

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from aquarom_fenics.io.scene import scene_from_dict  # noqa: E402

os.environ.setdefault("OMPI_ALLOW_RUN_AS_ROOT", "1")
os.environ.setdefault("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
os.environ.setdefault("OMPI_MCA_mpi_yield_when_idle", "1")   # a waiting rank yields its core to the other worker


FAULTS = "AQUAROM_TEST_FAULTS"
"""The folder where each xdist worker's fatal-error traceback goes (set by the controlling process)."""


@pytest.hookimpl(trylast=True)
def pytest_configure(config):
    """Ctrl-C as a terminal's foreground process gets it: the interrupt tests send SIGINT to the processes they
    start, and a shell starts background jobs with SIGINT ignored, which every process started after keeps
    (an ignored signal stays ignored across exec). The suite must answer the same however it is launched.
    Only the main thread may set a handler: an xdist worker configures in another thread under ``-v``.

    A worker that dies (a segmentation fault, an abort) is reported by xdist as "crashed" with no traceback in
    the summary; its faulthandler traceback went to the start of the output. Each worker writes it to a file of
    its own instead (after pytest's faulthandler has set itself up), and the controller prints the files at the
    end (:func:`pytest_terminal_summary`)."""
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.default_int_handler)
    if hasattr(config, "workerinput"):
        if os.environ.get(FAULTS):
            worker = os.environ.get("PYTEST_XDIST_WORKER", "worker")
            config._fault_file = open(Path(os.environ[FAULTS]) / f"{worker}-{os.getpid()}.txt", "w")
            faulthandler.enable(file=config._fault_file, all_threads=True)
    elif config.pluginmanager.hasplugin("xdist") and (config.getoption("numprocesses", None) or 0):
        config._fault_folder = Path(tempfile.mkdtemp(prefix="aquarom-test-faults-"))
        os.environ[FAULTS] = str(config._fault_folder)


def pytest_terminal_summary(terminalreporter, config):
    """The tracebacks of the workers that died, if any (see :func:`pytest_configure`)."""
    folder = getattr(config, "_fault_folder", None)
    for report in sorted(folder.iterdir()) if folder is not None else ():
        if report.stat().st_size:
            terminalreporter.section(f"fatal error in test worker {report.stem}")
            terminalreporter.write(report.read_text(errors="replace"))


def pytest_unconfigure(config):
    folder = getattr(config, "_fault_folder", None)
    if folder is not None:
        shutil.rmtree(folder, ignore_errors=True)


@pytest.fixture(autouse=True, scope="session")
def isolated_cache(tmp_path_factory):
    """FOM-check results are cached per test session, never in the repository."""
    os.environ["AQUAROM_CACHE"] = str(tmp_path_factory.mktemp("cache"))


@pytest.fixture(autouse=True)
def one_mpirun_at_a_time(request, tmp_path_factory):
    """A test marked ``mpi`` (``mpirun -n 2`` as a subprocess) holds an exclusive lock shared by the
    xdist workers of this run, so that two such tests never run at once on the two cores."""
    if request.node.get_closest_marker("mpi") is None or "PYTEST_XDIST_WORKER" not in os.environ:
        yield
        return
    lock = tmp_path_factory.getbasetemp().parent / "mpirun.lock"      # the run's folder, above each worker's
    with open(lock, "a") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)



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


def write_short_scene(directory, duration=0.2, extra="", name="scene.toml", template=SHORT_SCENE) -> str:
    """Write ``template`` (default :data:`SHORT_SCENE`) formatted with ``duration`` and ``extra`` as
    ``directory/name``; its path as a string, as the command line takes it."""
    path = directory / name
    path.write_text(template.format(duration=duration, extra=extra))
    return str(path)


def one_line(capsys) -> str:
    """The one error line on stderr (a `warning:` line before it, e.g. an --xi outside the bounds, aside)."""
    error = "\n".join(line for line in capsys.readouterr().err.strip().splitlines() if not line.startswith("warning:"))
    assert len(error.splitlines()) == 1 and "Traceback" not in error, error
    return error


def wait_for(condition, timeout: float = 120.0, what: str = "timed out") -> None:
    """Poll ``condition()`` every 0.05 s until it holds; fails with ``what`` after ``timeout`` seconds."""
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, what
        time.sleep(0.05)


def coarse_scene(**sections):
    """A scene on mesh level 1; keyword arguments are TOML tables, e.g. solver={"duration": 0.2}."""
    data = {"mesh": {"level": 1}}
    for name, table in sections.items():
        data[name] = {**data.get(name, {}), **table}
    return scene_from_dict(data, source="<test>")


MOVING_TAIL = {"xz_concave_tail": {"bounds": [-0.01, 0.2]}, "y_thin": {"bounds": [-0.15, 0.15]}}
"""Two shape parameters, the first of which moves the tail's rest stations (x and z), the second only widths."""

MOVING_TAIL_SWIM = {"duration": 0.3}

THRUST_VARIANTS = pytest.mark.parametrize("fluid", [
    {"spine_force": "lagrangian", "spine_rule": "rear"},
    {"spine_force": "lagrangian", "spine_rule": "trapezoid", "drag": False},
    {"spine_force": "source", "spine_rule": "rear", "drag": False},
    {"thrust_factor": 1.3, "drag_factor": 0.7},
], ids=["lagrangian-rear", "lagrangian-trapezoid-no-drag", "source-rear-no-drag", "fluid-factors"])
"""The thrust's variants a reduced kernel must follow: both spine rules and forces, with and without drag, fluid
factors (``@THRUST_VARIANTS`` on a test taking ``fluid``)."""


def moving_tail_designs(fluid: dict):
    """(scene, PROM, three designs ξ (3, 2), their amplitudes (3,)) of ``MOVING_TAIL`` with the thrust ``fluid``,
    on the coarsest mesh: the centre and two designs near opposite corners of the validity box, amplitudes around
    the scene's. The rest stations move with ξ (asserted)."""
    from aquarom_fenics.geometry.fish import load_fish
    from aquarom_fenics.reduction.reductor import build_prom

    scene = coarse_scene(shapes=MOVING_TAIL, solver=MOVING_TAIL_SWIM, fluid=fluid)
    prom = build_prom(scene, fish=load_fish(scene))
    assert prom.thrust is not None and np.any(prom.thrust.rest_xy_gradient)        # the rest stations move
    xis = prom.xi_center + prom.validity_radius * np.array([[0.0, 0.0], [0.9, -0.7], [-0.8, 0.6]])
    amplitudes = scene.actuation.amplitude * np.array([1.0, 1.1, 0.9])
    return scene, prom, xis, amplitudes


@pytest.fixture
def make_scene():
    return coarse_scene


def capped_block_scene(name: str, scale: float = 0.7) -> str:
    """The TOML of the capped atlas's test scene: the block on level 1, a 0.2 s swim, two shapes of radius
    0.05 / s (regular cells of half-width 0.05: 6 × 1 at the atlas scale s) and ``[reduction] validity_change``
    0.09, which caps the PROMs' radii below some cells (tests/studies/test_atlas_capped.py tells which)."""
    radius = 0.05 / scale
    return f"""
name = "{name}"
[mesh]
level = 1
[solver]
duration = 0.2
[reduction]
validity_change = 0.09
[shapes]
z_tail = {{ bounds = [-0.3, 0.3], radius = {radius!r} }}
y_thin = {{ bounds = [0.0, 0.1], radius = {radius!r} }}
"""


@pytest.fixture
def no_single_reduced_runs(monkeypatch):
    """Make any ``simulate_reduced`` call of the batched path fail: a sweep's designs must be integrated together."""
    from aquarom_fenics.dynamics import batched, reduced_dynamics

    def one_by_one(*args, **kwargs):
        raise AssertionError("a design of an atlas centre was integrated alone")

    monkeypatch.setattr(reduced_dynamics, "simulate_reduced", one_by_one)
    monkeypatch.setattr(batched, "simulate_reduced", one_by_one)


@pytest.fixture(scope="session")
def dask_cluster():
    """A real Dask distributed cluster on this machine: TCP scheduler, 2 worker processes of one
    thread each (made once, for the tests that ask for it)."""
    import logging

    from distributed import LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, protocol="tcp://", dashboard_address=None,
                      silence_logs=logging.ERROR) as cluster:
        yield cluster


@pytest.fixture(scope="module")
def quadratic_scene():
    """The coarsest mesh with quadratic tetrahedra (the default's degree)."""
    return coarse_scene(mesh={"degree": 2})


@pytest.fixture(scope="module")
def quadratic_fish(quadratic_scene):
    from aquarom_fenics.geometry.fish import load_fish
    return load_fish(quadratic_scene)
