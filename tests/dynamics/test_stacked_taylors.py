"""The batch's Taylor polynomials evaluated as one product (``batched_system.StackedTaylors``) against each
polynomial's own evaluation (``taylor_at``, ``taylor_gradient``)."""
import numpy as np
import pytest

from aquarom_fenics.dynamics.batched_system import StackedTaylors, taylor_at, taylor_gradient, taylor_weights
from aquarom_fenics.physics.taylor import Taylor


def random_taylor(rng, shape, p, order):
    second = None
    if order >= 2:
        second = rng.standard_normal((p, p) + shape)
        second = 0.5 * (second + np.swapaxes(second, 0, 1))         # a Hessian: symmetric in (k, l)
    return Taylor(rng.standard_normal(shape), rng.standard_normal((p,) + shape) if order >= 1 else None, second)


@pytest.mark.parametrize("p, orders", [(3, (2, 1, 0)), (2, (1, 1, 0)), (4, (0, 0, 0)), (0, (0, 0, 0))])
def test_stacked_values_and_gradients_are_each_polynomials_own(p, orders):
    rng = np.random.default_rng(p)
    shapes = [(4, 4), (), (2, 4, 4)]
    taylors = {f"t{n}": random_taylor(rng, shape, p, order) for n, (shape, order) in enumerate(zip(shapes, orders))}
    deltas = rng.uniform(-0.3, 0.3, (5, p))
    stacked = StackedTaylors(taylors, p)
    values, gradients = stacked.at(*taylor_weights(deltas, stacked.order))
    for name, taylor in taylors.items():
        np.testing.assert_allclose(values[name], taylor_at(taylor, deltas), rtol=1e-13, atol=1e-14)
        np.testing.assert_allclose(gradients[name], taylor_gradient(taylor, deltas), rtol=1e-13, atol=1e-14)
        assert values[name].shape == (5,) + np.shape(taylor.constant)
        assert gradients[name].shape == (5, p) + np.shape(taylor.constant)


def test_a_designs_values_do_not_depend_on_the_batch_it_is_in():
    """Bit for bit: the multi-start screen's costs of a batch are the optimiser's L of each design alone."""
    rng = np.random.default_rng(7)
    p = 5
    taylors = {"a": random_taylor(rng, (9, 9), p, 2), "b": random_taylor(rng, (3, 9), p, 1)}
    stacked = StackedTaylors(taylors, p)
    deltas = rng.uniform(-0.3, 0.3, (6, p))
    values, gradients = stacked.at(*taylor_weights(deltas, stacked.order))
    for b in range(6):
        alone, alone_gradients = stacked.at(*taylor_weights(deltas[b:b + 1], stacked.order))
        for name in taylors:
            assert np.array_equal(values[name][b], alone[name][0])
            assert np.array_equal(gradients[name][b], alone_gradients[name][0])
