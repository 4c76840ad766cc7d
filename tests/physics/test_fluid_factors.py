"""The fluid factors ``[fluid] thrust_factor`` c_T and ``drag_factor`` c_D: dimensionless, 1 by default
(SPEC's laws, the scene's hash unchanged), multiplying the Lighthill thrust and the skin drag of the FOM,
and of the reduced model through the tensors the FOM projects."""
import numpy as np
import pytest

from aquarom_fenics.cli import main
from aquarom_fenics.fem.fom import FullOrderModel
from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.reduction.reductor import build_prom
from conftest import coarse_scene, one_line

FACTORS = {"thrust_factor": 1.7, "drag_factor": 0.6}


def test_the_defaults_are_one_and_keep_the_scene_hash():
    scene = coarse_scene()
    assert (scene.fluid.thrust_factor, scene.fluid.drag_factor) == (1.0, 1.0)
    assert scene.hash == coarse_scene(fluid={"thrust_factor": 1, "drag_factor": 1.0}).hash
    assert scene.fom_hash == coarse_scene(fluid={"thrust_factor": 1.0}).fom_hash
    assert coarse_scene(fluid={"thrust_factor": 1.2}).hash != scene.hash
    assert coarse_scene(fluid={"drag_factor": 1.2}).fom_hash != scene.fom_hash
    assert "thrust_factor = 1.0" in scene.to_toml() and "drag_factor = 1.0" in scene.to_toml()


@pytest.mark.parametrize("key", ["thrust_factor", "drag_factor"])
@pytest.mark.parametrize("value", ["0", "-1.0", "nan", "inf", '"high"', "true"])
def test_a_bad_factor_is_one_line_and_exit_code_2(key, value, tmp_path, capsys):
    path = tmp_path / "bad.toml"
    path.write_text(f"[mesh]\nlevel = 1\n[fluid]\n{key} = {value}\n")
    assert main(["simulate", str(path), "--dry-run"]) == 2
    assert key in one_line(capsys)


@pytest.fixture(scope="module")
def models():
    """The level-1 FOM at the default factors and at :data:`FACTORS`."""
    plain = coarse_scene()
    factored = coarse_scene(fluid=FACTORS)
    fish = load_fish(plain)
    return FullOrderModel(plain, fish), FullOrderModel(factored, fish)


def test_the_factors_multiply_the_fom_thrust_and_drag(models):
    plain, factored = models
    rng = np.random.default_rng(3)
    u, v, a = (1e-3 * rng.standard_normal(plain.n_owned_dofs) for _ in range(3))
    thrust = plain.thrust.force(u, v, a)
    assert np.linalg.norm(thrust) > 0
    np.testing.assert_allclose(factored.thrust.force(u, v, a), FACTORS["thrust_factor"] * thrust, rtol=1e-12,
                               atol=1e-14 * np.abs(thrust).max())
    drag = plain.drag.force(v)
    assert np.linalg.norm(drag) > 0
    np.testing.assert_allclose(factored.drag.force(v), FACTORS["drag_factor"] * drag, rtol=1e-12,
                               atol=1e-14 * np.abs(drag).max())
    # the rest of the model is untouched
    np.testing.assert_array_equal(factored.internal_force(u), plain.internal_force(u))


def test_the_reduced_model_carries_the_factors_in_its_tensors():
    plain, factored = coarse_scene(), coarse_scene(fluid=FACTORS)
    fish = load_fish(plain)
    reference, scaled = build_prom(plain, fish=fish, parametric=False), build_prom(factored, fish=fish, parametric=False)
    np.testing.assert_allclose(scaled.basis, reference.basis, rtol=1e-9, atol=1e-12 * np.abs(reference.basis).max())
    assert scaled.thrust.fluid_density == pytest.approx(FACTORS["thrust_factor"] * reference.thrust.fluid_density,
                                                        rel=1e-15)
    np.testing.assert_allclose(scaled.drag.direction.constant, FACTORS["drag_factor"] * reference.drag.direction.constant,
                               rtol=1e-12, atol=1e-15 * np.abs(reference.drag.direction.constant).max())
