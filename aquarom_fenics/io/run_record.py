"""run.json of a resumable run: what makes its answers (scene hash, command, model, options),
written when it starts and compared by ``--resume``, which continues only the same run."""
from __future__ import annotations

import json
import logging
from pathlib import Path

from aquarom_fenics.errors import InputError
from aquarom_fenics.io.persistence import write_json_atomic
from aquarom_fenics.io.readback import load_run_record

log = logging.getLogger("aquarom")

RUN_RECORD = "run.json"
"""What makes a resumable run's answers (scene hash, command, model, options), written when it starts."""

RECORD_NAMES = {"scene_hash": "scene hash (the scene file, --set, --level, --degree)", "model": "--model",
                "method": "method (--method)", "cost_weights": "cost weights (--weight)", "start": "start point",
                "command": "command"}


def write_run_record(folder: Path, record: dict) -> None:
    """run.json in a resumable output folder (see :func:`check_run_record`)."""
    write_json_atomic(Path(folder) / RUN_RECORD, record)


def check_run_record(folder: Path, record: dict, warn_if_missing: bool = True) -> None:
    """Refuse (InputError naming the first difference) to resume a folder whose run.json records
    another run: another scene hash, command, model or option that changes the answers. A folder
    of an older version without run.json is resumed (with a warning, if ``warn_if_missing``)."""
    path = Path(folder) / RUN_RECORD
    if not path.exists() and not path.is_symlink():
        if not warn_if_missing:
            return
        log.warning("warning: --resume: %s has no %s (written by an older version): cannot check that it holds the same "
                    "run (scene, model, options)", folder, RUN_RECORD)
        return
    saved = load_run_record(path)
    for key, value in record.items():
        written = json.loads(json.dumps(saved.get(key)))
        if written != json.loads(json.dumps(value)):
            raise InputError(f"--resume: {folder} holds a run with {RECORD_NAMES.get(key, key)} {_shown(written)}, "
                             f"this run has {_shown(value)}; resume with the same options, or start without --resume "
                             "into another --out")


def _shown(value) -> str:
    return "none" if value is None else (value if isinstance(value, str) else json.dumps(value))
