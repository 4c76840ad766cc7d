"""The order of the package's layers: a module imports from its own layer and the layers below.

The data path reads bottom to top: files and scenes, the dolfinx adapter (and the run files, whose
XDMF meshes it makes), the geometry, the force terms, the FOM, the basis and reduced model, the runs
in time, the optimisers, the checks, the pictures, the studies of many runs, and the command line.
``tests/test_layers.py`` parses every module (imports inside functions included) and fails on an
import that runs upward and on any import cycle between modules.

A name is a module or a package of ``aquarom_fenics`` without the prefix; a module belongs to the
layer of its longest listed name (``fem.dolfinx_adapter`` before ``fem``); ``""`` is the package's
``__init__`` (the logger and version).
"""
from __future__ import annotations

LAYERS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("base", ("", "errors", "files", "layers", "machine_code")),
    ("parallel", ("parallel",)),
    ("forms", ("forms", "scenes", "meshes")),
    ("shape catalogue", ("geometry.shapes", "geometry.shape_registry")),
    ("io", ("io",)),
    ("discretisation", ("fem.jit_cache", "fem.dolfinx_adapter", "fem.cellwise", "fem.pair_kernel")),
    ("run files", ("io.xdmf", "io.run_outputs")),
    ("geometry", ("geometry",)),
    ("physics", ("physics",)),
    ("fem", ("fem",)),
    ("reduction", ("reduction",)),
    ("dynamics", ("dynamics",)),
    ("screening", ("verification.local_stability",)),
    ("optimization", ("optimization",)),
    ("verification", ("verification",)),
    ("calibration", ("calibration",)),
    ("viz", ("viz",)),
    ("studies", ("studies", "verification.validation")),
    ("interface", ("cli", "api")),
)
"""(layer, names) from the bottom up."""

PACKAGE = "aquarom_fenics"


def layer_of(module: str) -> int:
    """Position in :data:`LAYERS` of a module (``aquarom_fenics.fem.fom``) by its longest listed name;
    ValueError for a module no layer lists."""
    relative = module[len(PACKAGE) + 1:] if module.startswith(PACKAGE + ".") else "" if module == PACKAGE else None
    if relative is None:
        raise ValueError(f"{module}: not a module of {PACKAGE}")
    matches = [(len(name), index) for index, (_, names) in enumerate(LAYERS) for name in names
               if name == relative or (name and relative.startswith(name + "."))]
    if not matches:
        raise ValueError(f"{module}: in no layer of aquarom_fenics.layers.LAYERS; add its folder there")
    return max(matches)[1]


def layer_name(module: str) -> str:
    """The name of the layer of ``module``."""
    return LAYERS[layer_of(module)][0]
