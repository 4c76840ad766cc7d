"""The start design's FOM run in a child process while the optimiser works.

The FOM check after an optimisation needs two FOM runs, the start design's and the
optimum's. The start design's is known before the optimisation starts: on a single MPI rank with a
spare core, a child process runs it meanwhile and stores its distance in the FOM cache
(``study.fom_distance``), where the check finds it. If the child fails or is still running when
the check has finished the optimum's run and waited as long again, the check runs it itself.

    python -m aquarom_fenics.optimization.background_fom SCENE.toml DESIGN.json   (the child)
"""
from __future__ import annotations

import json
import logging
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from mpi4py import MPI

from aquarom_fenics.io.scene import Scene

log = logging.getLogger("aquarom")

GRACE = 60.0
"""Seconds the check waits for the child beyond the duration of its own FOM run."""


class BackgroundFom:
    """A child process computing ``fom_distance(scene, fish, design, amplitude)`` into the FOM cache."""

    def __init__(self, scene: Scene, design: dict[str, float], amplitude: float | None):
        self.folder = Path(tempfile.mkdtemp(prefix="aquarom-start-fom-"))
        scene_file, design_file = self.folder / "scene.toml", self.folder / "design.json"
        scene_file.write_text(scene.to_toml())
        design_file.write_text(json.dumps({"design": design, "amplitude": amplitude}))
        self.started = time.perf_counter()
        self.process = subprocess.Popen([sys.executable, "-m", __name__, str(scene_file), str(design_file)],
                                         stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                         stderr=subprocess.DEVNULL, env=dict(os.environ, OMP_NUM_THREADS="1"))
        log.info("FOM check: the start design's FOM runs in a background process during the optimisation")

    def finish(self, patience: float) -> None:
        """Wait for the child at most ``patience`` + GRACE seconds, then stop it; remove its files."""
        try:
            self.process.wait(timeout=patience + GRACE)
            if self.process.returncode != 0:
                log.warning("FOM check: the background run of the start design failed (exit %d); "
                            "running it here", self.process.returncode)
        except subprocess.TimeoutExpired:
            log.warning("FOM check: the background run of the start design is still running after %.0f s; "
                        "stopping it and running it here", time.perf_counter() - self.started)
            self.stop()
        finally:
            self._remove_files()

    def stop(self) -> None:
        """Terminate the child (optimisation interrupted or failed) and remove its files."""
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait(timeout=10)
        self._remove_files()

    def _remove_files(self) -> None:
        for name in ("scene.toml", "design.json"):
            (self.folder / name).unlink(missing_ok=True)
        try:
            self.folder.rmdir()
        except OSError:
            pass


def start_if_useful(scene: Scene, design: dict[str, float], amplitude: float | None, cached: bool) -> BackgroundFom | None:
    """A background run of the start design's FOM, or None: on several MPI ranks (they use the cores), on one
    core, or when the start distance is in the cache already."""
    if cached or MPI.COMM_WORLD.size > 1 or (os.cpu_count() or 1) < 2:
        return None
    return BackgroundFom(scene, design, amplitude)


def main(argv: list[str]) -> int:
    from aquarom_fenics.geometry.fish import load_fish
    from aquarom_fenics.optimization.study import fom_distance

    scene = Scene.load(argv[0])
    request = json.loads(Path(argv[1]).read_text())
    fom_distance(scene, load_fish(scene), request["design"], request["amplitude"])
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
