"""Where many runs go: the ``[cluster]`` table of a scene and the command line's choice."""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from aquarom_fenics.errors import InputError
from aquarom_fenics.parallel.addresses import check_address

DEFAULT_CONNECT_TIMEOUT = 10.0
"""Seconds to wait for a Dask scheduler before the command is refused."""


@dataclass(frozen=True)
class ClusterSettings:
    """Where the work goes: a Dask scheduler (``scheduler`` address or ``scheduler_file``) or,
    with neither, local worker processes. ``connect_timeout`` [s] bounds the wait for the scheduler."""

    scheduler: str = ""
    scheduler_file: str = ""
    connect_timeout: float = DEFAULT_CONNECT_TIMEOUT

    @property
    def distributed(self) -> bool:
        return bool(self.scheduler or self.scheduler_file)

    def describe(self) -> str:
        if self.scheduler:
            return f"Dask scheduler {self.scheduler}"
        if self.scheduler_file:
            return f"Dask scheduler of {self.scheduler_file}"
        return "local worker processes"


CLUSTER_KEYS = {"scheduler": str, "scheduler_file": str, "connect_timeout": float}


def cluster_from_table(table: dict, where: str, base_dir: str = ".") -> ClusterSettings:
    """The ``[cluster]`` table of a scene or configuration file; a relative scheduler file is taken
    relative to ``base_dir`` (the file's folder). InputError names a bad key or value."""
    if not isinstance(table, dict):
        raise InputError(f"{where}: [cluster] must be a table, got {table!r}")
    values = {}
    for key, value in table.items():
        if key not in CLUSTER_KEYS:
            raise InputError(f"{where}: unknown key [cluster] {key}; valid keys: {', '.join(CLUSTER_KEYS)}")
        if CLUSTER_KEYS[key] is str and not isinstance(value, str):
            raise InputError(f"{where}: [cluster] {key} must be a string, got {value!r}")
        if CLUSTER_KEYS[key] is float:
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
                raise InputError(f"{where}: [cluster] {key} must be a positive number of seconds, got {value!r}")
            value = float(value)
        values[key] = value
    if values.get("scheduler") and values.get("scheduler_file"):
        raise InputError(f"{where}: [cluster] give scheduler or scheduler_file, not both")
    if values.get("scheduler_file"):
        values["scheduler_file"] = str(Path(base_dir) / values["scheduler_file"])
    return ClusterSettings(**values)


def choose_cluster(scheduler: str | None, scheduler_file: Path | None,
                   configured: ClusterSettings | None = None, connect_timeout: float | None = None) -> ClusterSettings:
    """The command line's --scheduler / --scheduler-file, else the configured ``[cluster]``, else local."""
    if scheduler and scheduler_file:
        raise InputError("--scheduler and --scheduler-file: give one of them")
    if scheduler is not None and not scheduler.strip():
        raise InputError(f"--scheduler {scheduler!r}: an empty address; give one such as tcp://head-node:8786, "
                         "or leave --scheduler out to run on local worker processes")
    if scheduler_file is not None and not str(scheduler_file).strip():
        raise InputError("--scheduler-file '': an empty file name; give the file `dask scheduler --scheduler-file` writes")
    base = configured or ClusterSettings()
    timeout = base.connect_timeout if connect_timeout is None else connect_timeout
    if not (timeout > 0 and math.isfinite(timeout)):
        raise InputError(f"--connect-timeout {timeout}: must be a positive, finite number of seconds")
    if scheduler:
        check_address(scheduler, f"--scheduler {scheduler}")
    if scheduler or scheduler_file:
        return ClusterSettings(scheduler or "", str(scheduler_file or ""), timeout)
    return ClusterSettings(base.scheduler, base.scheduler_file, timeout)
