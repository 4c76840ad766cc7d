"""What computed a result: the versions of the toolkit and its stack, the git commit of a checkout."""
from __future__ import annotations

import os
import platform
import subprocess
from pathlib import Path

import numpy as np


def software_versions() -> dict[str, str]:
    import dolfinx
    import petsc4py
    import ufl

    from aquarom_fenics import __version__

    return {"aquarom_fenics": __version__, "dolfinx": dolfinx.__version__, "petsc4py": petsc4py.__version__,
            "ufl": ufl.__version__, "numpy": np.__version__, "python": platform.python_version()}


def git_commit(repository: Path) -> str:
    """The commit checked out in `repository`, else $AQUAROM_GIT_COMMIT, else "unknown".

    Only a checkout whose top level is `repository` itself counts (not one that merely contains a
    copy of it); an image built without the history is given the commit in AQUAROM_GIT_COMMIT.
    """
    try:
        answer = subprocess.run(["git", "-C", str(repository), "rev-parse", "--show-toplevel", "HEAD"],
                                capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired):   # no git, or git hangs
        answer = None
    lines = answer.stdout.splitlines() if answer is not None and answer.returncode == 0 else []
    if len(lines) == 2 and Path(lines[0]).resolve() == Path(repository).resolve():
        return lines[1]
    return os.environ.get("AQUAROM_GIT_COMMIT") or "unknown"
