"""The compiled reduced kernel (``reduced_kernel``) against ``simulate_reduced`` on every variant of the thrust law
(rear and trapezoid rules, the source's and the lagrangian spine force, fixed and moving rest stations) and
without drag; and its one compiled signature."""
import numpy as np
import pytest

from aquarom_fenics.dynamics import reduced_kernel
from aquarom_fenics.dynamics.batched import simulate_batch
from prom_checks import assert_batch_matches_single_runs
from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.reduction.reductor import build_prom
from conftest import THRUST_VARIANTS, coarse_scene, moving_tail_designs

pytestmark = pytest.mark.skipif(not reduced_kernel.available(), reason="numba is not installed")


@THRUST_VARIANTS
def test_the_kernel_agrees_with_single_runs_on_each_thrust_variant(fluid):
    scene, prom, xis, amplitudes = moving_tail_designs(fluid)
    batch = simulate_batch(prom, scene, xis, sensitivities=True, amplitudes=amplitudes, amplitude_sensitivity=True,
                           engine="compiled")
    assert_batch_matches_single_runs(prom, scene, xis, amplitudes, batch)


def test_the_kernel_has_one_compiled_signature_for_a_real_batch_and_the_warm_up():
    """``make setup`` compiles the kernel once on a synthetic batch (``warm_up``); a real batch must reuse that
    machine code, not compile a second signature (half a minute on a user's first sweep)."""
    reduced_kernel.warm_up()
    scene = coarse_scene(solver={"duration": 0.1})
    prom = build_prom(scene, fish=load_fish(scene))
    simulate_batch(prom, scene, np.zeros((2, 0)), engine="compiled")
    assert len(reduced_kernel.integrate_all.signatures) == 1


def test_an_unknown_engine_is_refused():
    scene = coarse_scene(solver={"duration": 0.1})
    with pytest.raises(ValueError, match="engine must be one of"):
        simulate_batch(None, scene, np.zeros((1, 0)), engine="fortran")


def test_a_change_to_any_kernel_module_discards_the_cached_kernel(tmp_path):
    """numba checks only a function's own file: the set-up's warm-up removes the kernel's cache when any of its
    modules changed (the entry's machine code includes its callees'), and keeps it otherwise."""
    from pathlib import Path

    from aquarom_fenics.dynamics import compiled

    source = Path(compiled.__file__).parent
    for name in compiled.KERNEL_MODULES:
        (tmp_path / f"{name}.py").write_bytes((source / f"{name}.py").read_bytes())
    cache = tmp_path / "__pycache__"
    cache.mkdir()
    cached = [cache / "reduced_kernel.integrate_all-10.py311.nbi", cache / "kernel_thrust.half_blocks-5.py311.1.nbc"]
    unrelated = cache / "batched.cpython-311.pyc"
    for path in cached + [unrelated]:
        path.write_bytes(b"x")
    assert compiled.refresh_stale_cache(tmp_path)                         # no record yet: discarded
    assert not any(path.exists() for path in cached) and unrelated.exists()
    for path in cached:
        path.write_bytes(b"x")
    assert not compiled.refresh_stale_cache(tmp_path)                     # same sources: kept
    assert all(path.exists() for path in cached)
    thrust = tmp_path / "kernel_thrust.py"
    thrust.write_text(thrust.read_text() + "\n# changed\n")
    assert compiled.refresh_stale_cache(tmp_path)                         # a callee's module changed
    assert not any(path.exists() for path in cached) and unrelated.exists()
