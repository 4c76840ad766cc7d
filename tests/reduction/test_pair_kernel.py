"""The compiled whitened pair products (fem/pair_kernel.py) equal numpy's (fem/cellwise.strain_coefficients, then
the whitening) to 1e-12 relative: degree 1 and 2, Taylor order 2, the shared and the per-sample whitening; and the
internal force's Taylor terms formed with them (the Leibniz terms' weights in the kernel) equal numpy's."""
import numpy as np
import pytest
from mpi4py import MPI

from aquarom_fenics.fem import pair_kernel
from aquarom_fenics.fem.cellwise import CellSampler, Whitening, internal_force_taylor
from aquarom_fenics.fem.fom import FullOrderModel
from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.reduction.basis import build_basis
from conftest import coarse_scene
from prom_checks import SO1_SHAPES

pytestmark = pytest.mark.skipif(not pair_kernel.available(), reason="numba is not installed")


def sampler_and_basis(degree):
    scene = coarse_scene(mesh={"degree": degree}, shapes=SO1_SHAPES)
    model = FullOrderModel(scene, load_fish(scene), np.array([0.1, -0.2, 0.05]))
    return CellSampler(model, 2, 3), build_basis(model, 3).vectors


@pytest.mark.parametrize("degree", [1, 2])
def test_compiled_pair_products_equal_numpys(degree):
    """(ẽ, q̃) of E and of every first and second ξ-derivative, off the nominal design (a term is zero where the
    shape directions' supports are apart), a region's samples only for the per-sample factors; the region's zeros kept."""
    sampler, vectors = sampler_and_basis(degree)
    assert len(sampler.strain_indices) == 1 + 3 + 6
    weight, moduli = sampler.weights(sampler.weight[0]), sampler.elasticity()
    region = np.random.default_rng(5).random(sampler.n_samples) < 0.5
    for transform in (Whitening(weight, moduli), Whitening(weight, moduli, region, allow_shared=False)):
        compiled = sampler.whitened_strain_coefficients(vectors, transform, compiled=True)
        reference = sampler.whitened_strain_coefficients(vectors, transform, compiled=False)
        assert list(compiled) == list(reference) == sampler.strain_indices
        assert sum(reference[indices][1].any() for indices in reference) >= 6
        for indices in sampler.strain_indices:
            for part, (value, expected) in enumerate(zip(compiled[indices], reference[indices])):
                assert value.shape == expected.shape
                scale = np.abs(expected).max()      # zero where ∂_kl H = 0 (e of a second derivative)
                assert np.abs(value - expected).max() <= 1e-12 * scale, (transform.shared, indices, part)
        if not transform.shared:
            assert not np.any(compiled[()][1][:, :, ~region])


@pytest.mark.parametrize("degree", [1, 2])
def test_compiled_internal_force_equals_numpys(degree):
    """K1, K2, K3 and their first and second ξ-derivatives, on all samples and on a region's, to 1e-12."""
    sampler, vectors = sampler_and_basis(degree)
    region = np.random.default_rng(7).random(sampler.n_samples) < 0.5
    for samples in (None, region):
        compiled, reference = (internal_force_taylor(sampler, vectors, 3, 2, MPI.COMM_WORLD, samples, compiled=flag)
                               for flag in (True, False))
        assert len(compiled) == len(reference) == 3
        for term, (new, expected_term) in enumerate(zip(compiled, reference)):
            for power, (value, expected) in enumerate(zip(new, expected_term)):
                scale = np.abs(expected).max()
                assert scale > 0
                assert np.abs(value - expected).max() <= 1e-12 * scale, (samples is None, term, power)
