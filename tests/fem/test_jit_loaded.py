"""A module dolfinx's JIT loaded once in a process is not loaded again (fem/dolfinx_adapter.py, ``_LOADED``): FFCx
would list the cache folder and hash the object a second time, about 3 ms a load."""
import numpy as np
import ufl
from mpi4py import MPI

from aquarom_fenics.fem import dolfinx_adapter as fx
from aquarom_fenics.fem.jit_cache import CACHE_VARIABLE
from tests.fem.jit_probe import probe_mesh


def weighted_mass(weight: float):
    """∫ c u·v dx on a new mesh, c a cell field equal to ``weight``: its assembled matrix."""
    mesh = probe_mesh(MPI.COMM_SELF)
    space = fx.vector_space(mesh, 2)
    field = fx.new_function(fx.cellwise_constant_space(mesh), "c")
    field.x.array[:] = weight
    form = fx.compile_form(0.5432 * field * ufl.inner(ufl.TrialFunction(space), ufl.TestFunction(space)) * ufl.dx)
    return fx.assemble_matrix_into(fx.create_matrix(form), form).getValuesCSR()[2]


def test_a_module_is_loaded_once_a_process_and_binds_the_new_forms_fields(tmp_path, monkeypatch):
    calls = []
    loader = fx._FFCX_JIT
    monkeypatch.setattr(fx, "_FFCX_JIT", lambda *args, **kwargs: calls.append(args[1]) or loader(*args, **kwargs))
    monkeypatch.setenv(CACHE_VARIABLE, str(tmp_path / "first"))
    once = weighted_mass(1.0)
    assert len(calls) == 3                          # the displacement's element, the field's element, the form
    twice = weighted_mass(2.0)
    assert len(calls) == 3                          # all three loaded before: FFCx not asked again
    np.testing.assert_allclose(twice, 2.0 * once, rtol=1e-14)
    assert np.abs(once).max() > 0
    monkeypatch.setenv(CACHE_VARIABLE, str(tmp_path / "second"))
    weighted_mass(1.0)
    assert len(calls) == 6                          # another cache folder: its own modules
