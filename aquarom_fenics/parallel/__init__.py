"""Many independent runs: a ``concurrent.futures``-shaped pool of workers and the cluster settings.

Every many-run job (a design sweep, the validation cases, the nominal FOM run beside an
optimisation) submits plain functions to a pool:

* :class:`LocalProcesses` (the default): fresh interpreters on this machine (``spawn``), each with
  one BLAS/OpenMP thread; nothing to start beforehand.
* :class:`DaskCluster`: the workers of a running Dask distributed scheduler
  (``dask.distributed.Client``), given by its address (``tcp://host:8786``), by the JSON file
  ``dask scheduler --scheduler-file`` writes, or by a ``[cluster]`` table of a scene.
* :class:`InProcess`: one worker and no cluster runs each task here, at submission (serial).

Nothing here knows what the tasks compute: the caller hands a :class:`WorkerSetup` (the variables
each task needs, what a long-lived worker does when it starts) to the pool it opens.
"""
from aquarom_fenics.parallel.addresses import check_address, scheduler_file_address
from aquarom_fenics.parallel.dask_cluster import DaskCluster, connect, usable_workers, worker_import_error
from aquarom_fenics.parallel.in_process import InProcess
from aquarom_fenics.parallel.interface import Pool, WorkerSetup, in_worker, run_task, worker_name, worker_threads
from aquarom_fenics.parallel.local import STOP_GRACE, THREAD_VARIABLES, LocalProcesses
from aquarom_fenics.parallel.run import LOCAL_RESTARTS, open_pool, run_all, shutting_down
from aquarom_fenics.parallel.settings import (CLUSTER_KEYS, DEFAULT_CONNECT_TIMEOUT, ClusterSettings, choose_cluster,
                                               cluster_from_table)

__all__ = ["CLUSTER_KEYS", "DEFAULT_CONNECT_TIMEOUT", "LOCAL_RESTARTS", "STOP_GRACE", "THREAD_VARIABLES",
           "ClusterSettings", "DaskCluster", "InProcess", "LocalProcesses", "Pool", "WorkerSetup", "check_address",
           "choose_cluster", "cluster_from_table", "connect", "in_worker", "open_pool", "run_all", "run_task",
           "scheduler_file_address", "shutting_down", "usable_workers", "worker_import_error", "worker_name",
           "worker_threads"]
