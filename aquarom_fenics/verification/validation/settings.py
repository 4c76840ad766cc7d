"""Settings of the validation (full and quick) and the scenes its studies start from."""
from __future__ import annotations

from dataclasses import dataclass

from aquarom_fenics.io.scene import Scene

REFERENCE_STIFFNESS = 6e4
"""k [Pa] of the reference fish (SPEC §5)."""

PROM_SCENES = {3: "so1", 5: "so2", 8: "so3"}
"""Number of shape parameters → shipped scene whose shape set the PROM carries."""


@dataclass(frozen=True)
class Settings:
    quick: bool
    levels: tuple[int, ...]                  # studies a and b, at study_degree
    stiffnesses: tuple[float, ...]          # Pa; calibrated on level 1 (amplitude ∝ k): 0.5–3.3 cm on level 3
    duration: float                          # s
    reference_level: int
    time_steps: tuple[float, ...]            # study c
    convergence_steps: tuple[float, ...]     # study d: the window every model and scheme runs
    finer_convergence_steps: tuple[tuple[str, tuple[float, ...]], ...]   # study d, default scheme: (model, finer steps)
    convergence_mesh: tuple[int, int] | None  # study d: (degree, level); None: each shipped scene's own mesh
    mpi_levels: tuple[int, ...]              # study e, at study_degree
    stress_level: int
    fine_prom_level: int
    time_limit: float                        # s per case
    mesh_series: tuple[tuple[int, tuple[int, ...]], ...]   # (degree, levels) of the mesh-convergence study
    station_counts: tuple[int, ...] = (20, 40, 80, 160)      # N_s of the station study
    station_mesh: tuple[int, int] = (2, 1)                    # its (degree, level): the shipped default
    study_degree: int = 2                                     # element degree of studies a, b and e (the shipped one)
    fish_levels: tuple[int, ...] = (1, 2, 3, 4)               # the shipped fish's meshes (meshes/fish.toml), degree 2


FULL = Settings(quick=False, levels=(1, 2, 3), stiffnesses=(1.2e4, 2.5e4, 4e4, 6e4, 7.5e4), duration=2.0,
                reference_level=3, time_steps=(0.04, 0.02, 0.01, 0.005), convergence_steps=(0.02, 0.01, 0.005, 0.0025),
                finer_convergence_steps=(("FOM", (0.00125,)), ("ROM", (0.00125, 0.000625, 0.0003125)),
                                         ("PROM", (0.00125, 0.000625, 0.0003125))),
                convergence_mesh=None, mpi_levels=(2, 3), stress_level=3, fine_prom_level=5, time_limit=1800.0,
                mesh_series=((1, (1, 2, 3, 4, 5)), (2, (1, 2, 3, 4, 5))))
QUICK = Settings(quick=True, levels=(1, 2), stiffnesses=(1.2e4, 6e4, 7.5e4), duration=0.4, reference_level=1,
                 time_steps=(0.04, 0.02, 0.01, 0.005), convergence_steps=(0.02, 0.01, 0.005, 0.0025),
                 finer_convergence_steps=(("ROM", (0.00125,)),), convergence_mesh=(1, 1), mpi_levels=(1, 2), stress_level=1, fine_prom_level=2, time_limit=300.0,
                 mesh_series=((1, (1, 2, 3)), (2, (1,))), station_counts=(10, 20, 40), station_mesh=(1, 1),
                 study_degree=1, fish_levels=(1, 2, 3))


def base_scene(settings: Settings, name: str = "nominal", level: int | None = None,
               stiffness: float = REFERENCE_STIFFNESS, time_step: float = 0.02, solver: dict | None = None,
               degree: int = 1):
    """A shipped scene at the study's level (linear tetrahedra unless ``degree`` says otherwise: studies
    c, d and the stress cases stay on SPEC §11's linear levels; a, b and e pass ``study_degree``),
    stiffness, horizon and step; ``solver`` overrides [solver] values."""
    scene = Scene.load(name)
    scene = scene.replace("mesh", level=level or settings.reference_level, degree=degree)
    scene = scene.replace("actuation", stiffness=float(stiffness))
    scene = scene.replace("solver", duration=settings.duration, time_step=float(time_step), **(solver or {}))
    return scene.replace("output", plots=False, render=False, xdmf=False)


def fish_scene(settings: Settings, level: int) -> Scene:
    """The shipped fish scene (``scenes/fish.toml``, degree 2) on the shipped mesh of ``level``
    (``meshes/fish_l<level>.msh``) over the study's horizon."""
    from aquarom_fenics.geometry.fish_recipe import shipped_fish_path

    scene = Scene.load("fish").replace("mesh", file=str(shipped_fish_path(level)))
    scene = scene.replace("solver", duration=settings.duration)
    return scene.replace("output", plots=False, render=False, xdmf=False)


def kpa(stiffness: float) -> str:
    return f"{stiffness / 1e3:g} kPa"
