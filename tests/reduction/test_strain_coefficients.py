"""The internal-force tensors from the relative displacement gradients (fem/cellwise.py) equal those of
the forms' Green-Lagrange strain sampled at u = ±V_j and u = V_j + V_k (E is quadratic in u)."""
import numpy as np
import pytest
import ufl
from mpi4py import MPI

from aquarom_fenics.fem import dolfinx_adapter as fx
from aquarom_fenics.fem.cellwise import (CellSampler, Whitening, internal_force_taylor, leibniz_terms, pair_list,
                                        symmetric_coordinates, whiten)
from aquarom_fenics.fem.fom import FullOrderModel
from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.reduction.basis import build_basis
from conftest import coarse_scene
from forms.kinematics import green_lagrange_strain
from prom_checks import SO1_SHAPES


class SampledStrain(CellSampler):
    """The strain coefficients sampled from the forms' E(u) itself, three evaluations per basis vector and pair."""

    def __init__(self, fom, taylor_order, n_parameters):
        super().__init__(fom, taylor_order, n_parameters)
        strain = green_lagrange_strain(self.direction, fom.shape_gradients["stiffness"])
        derivatives = {(): strain}
        for k, direction in enumerate(self.parameter_directions):
            derivatives[k,] = fom.shape_derivative(strain, direction)
        for k, l in self.strain_indices[1 + len(self.parameter_directions):]:
            derivatives[k, l] = fom.shape_derivative(derivatives[k,], self.parameter_directions[l])
        self.strains = self._compile(ufl.as_vector([tensor[i, j] for indices in self.strain_indices
                                                    for tensor in [derivatives[indices]]
                                                    for i in range(3) for j in range(3)]))

    def whitened_strain_coefficients(self, vectors, transform, compiled=None):
        count, m = len(self.strain_indices), vectors.shape[1]

        def strains_of(owned):          # (count, 6, n_samples)
            fx.set_owned_values(self.direction, owned)
            values = self.evaluate(self.strains, 9 * count).reshape(self.n_samples, count, 9)
            return symmetric_coordinates(values).transpose(1, 2, 0)

        plus = np.stack([strains_of(vectors[:, j]) for j in range(m)], axis=1)
        minus = np.stack([strains_of(-vectors[:, j]) for j in range(m)], axis=1)
        linear, diagonal = (plus - minus) / 2.0, plus + minus
        quadratic = np.stack([diagonal[:, j] if j == k else
                              strains_of(vectors[:, j] + vectors[:, k]) - linear[:, j] - linear[:, k]
                              - 0.5 * (diagonal[:, j] + diagonal[:, k]) for j, k in pair_list(m)], axis=1)
        return {indices: (whiten(linear[i], transform), whiten(quadratic[i], transform))
                for i, indices in enumerate(self.strain_indices)}


@pytest.mark.parametrize("degree, order", [(1, 2), (2, 1)])
def test_tensors_from_the_gradients_equal_the_sampled_strains(degree, order):
    """K1, K2, K3 and their ξ-derivatives (second ones at order 2), off the nominal design, to 1e-12 (the tensors
    from the gradients by the compiled pair products where numba is installed)."""
    scene = coarse_scene(mesh={"degree": degree}, shapes=SO1_SHAPES)
    model = FullOrderModel(scene, load_fish(scene), np.array([0.1, -0.2, 0.05]))
    vectors = build_basis(model, 3).vectors
    computed = internal_force_taylor(CellSampler(model, order, 3), vectors, 3, order, MPI.COMM_WORLD)
    sampled = internal_force_taylor(SampledStrain(model, order, 3), vectors, 3, order, MPI.COMM_WORLD, compiled=False)
    assert len(computed) == len(sampled) == 1 + order
    for term, (new, reference) in enumerate(zip(computed, sampled)):
        for power, (value, expected) in enumerate(zip(new, reference)):
            scale = np.abs(expected).max()
            assert scale > 0
            assert np.abs(value - expected).max() <= 1e-12 * scale, (term, power)


def test_whitening_shared_and_per_sample_factors_give_the_weighted_energy():
    """(R_sᵀ x)·(R_sᵀ y) = w_s x:ℂ_s:y at every sample, with one shared factor (ℂ_s = c_s ℂ̂: the head's stiffer
    cells) and with a factor per sample; zero outside a region's samples."""
    scene = coarse_scene(shapes=SO1_SHAPES)
    sampler = CellSampler(FullOrderModel(scene, load_fish(scene), np.zeros(3)), 0, 3)
    moduli, weight = sampler.elasticity(), sampler.weights(sampler.weight[0])
    assert np.unique(np.round(moduli[:, 0, 0], 6)).size == 2          # two moduli: a shared shape, two scales
    rng = np.random.default_rng(3)
    x, y = rng.standard_normal((2, 2, 6, sampler.n_samples))
    expected = weight * np.einsum("kas,sab,kbs->ks", x, moduli, y)
    region = rng.random(sampler.n_samples) < 0.5
    for allow_shared in (True, False):
        for samples in (None, region):
            transform = Whitening(weight, moduli, samples, allow_shared=allow_shared)
            assert transform.shared == allow_shared
            value = np.einsum("kas,kas->ks", whiten(x, transform), whiten(y, transform))
            target = expected if samples is None else expected * samples
            assert np.abs(value - target).max() <= 1e-13 * np.abs(expected).max()
    bent = moduli.copy()
    bent[0, 0, 1] = bent[0, 1, 0] = 1.01 * moduli[0, 0, 1]               # one sample's law differs: no shared factor
    assert not Whitening(weight, bent).shared


def test_leibniz_terms_distribute_every_index_to_one_factor():
    """∂_kl (f g h): 9 terms, each index on one factor, each factor's indices sorted; the product rule's count."""
    terms = list(leibniz_terms((0, 2), 3))
    assert len(terms) == 9 and len(set(terms)) == 9
    assert ((0, 2), (), ()) in terms and ((), (0,), (2,)) in terms and ((), (2,), (0,)) in terms
    assert all(sorted(a + b + c) == [0, 2] for a, b, c in terms)
    assert list(leibniz_terms((), 2)) == [((), ())]
    assert list(leibniz_terms((1, 1), 2)) == [((1, 1), ()), ((1,), (1,)), ((1,), (1,)), ((), (1, 1))]
