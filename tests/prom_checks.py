"""Checks of a PROM against its FOM shared by the PROM tests of either element degree."""
import numpy as np

from aquarom_fenics.dynamics.integrator import TimeScheme
from aquarom_fenics.dynamics.reduced_dynamics import ReducedSystem
from aquarom_fenics.fem.fom import FullOrderModel
from aquarom_fenics.reduction.projection import project_vector

SO1_SHAPES = {"z_tail": {"bounds": [-0.5, 0.5]}, "z_head": {"bounds": [-0.5, 0.5]},
              "y_thin": {"bounds": [-0.15, 0.15]}}


def relative_error(actual, expected):
    return np.linalg.norm(np.asarray(actual) - np.asarray(expected)) / np.linalg.norm(expected)


class ProjectedFOM:
    """Vᵀ r_FOM(V η, V η̇, V η̈) of a design (pulled back with its exact shape gradient, the
    reference of SPEC §5, or meshed directly), with the PROM's basis V."""

    def __init__(self, scene, fish, prom, xi, moved_mesh=False):
        self.model = FullOrderModel(scene, fish, xi, moved_mesh=moved_mesh)
        self.vectors = np.column_stack([self.model.owned_values(prom.basis[:, :, j]) for j in range(prom.size)])

    def residual(self, time, eta, eta_dot, eta_ddot):
        V = self.vectors
        return project_vector(self.model.comm, V, self.model.residual(time, V @ eta, V @ eta_dot, V @ eta_ddot)[0])

    def internal_force(self, eta):
        return project_vector(self.model.comm, self.vectors, self.model.internal_force(self.vectors @ eta))


def random_states(rng, m, scale):
    return [scale * rng.standard_normal(m) for _ in range(3)]


def assert_prom_reproduces_the_projected_fom_forces(scene, fish, prom, samples):
    """Vᵀ r of the FOM and the PROM's residual and internal force agree to 1e-9 at random states (SPEC §8)."""
    projected = ProjectedFOM(scene, fish, prom, prom.xi_center)
    system = ReducedSystem(prom, scene, prom.xi_center, TimeScheme.newmark(0.02, 0.005))
    rng = np.random.default_rng(0)
    for sample in range(samples):
        eta, eta_dot, eta_ddot = random_states(rng, prom.size, 0.02)
        time = 0.05 * (sample + 1)
        expected = projected.residual(time, eta, eta_dot, eta_ddot)
        assert relative_error(system.residual(time, eta, eta_dot, eta_ddot)[0], expected) < 1e-9
        assert relative_error(system.internal_force(eta), projected.internal_force(eta)) < 1e-9


def assert_first_xi_derivative_matches_the_fom(scene, fish, prom):
    """∂/∂ξ_k Vᵀ f_int(Vη; ξ): PROM Taylor term against a 4th-order central difference of the FOM."""
    eta = 0.02 * np.random.default_rng(2).standard_normal(prom.size)
    system = ReducedSystem(prom, scene, prom.xi_center, TimeScheme.newmark(0.02, 0.005))
    derivative = system.internal_force_gradient(eta)
    step = 2e-3

    def projected_force(offset):
        return ProjectedFOM(scene, fish, prom, prom.xi_center + offset).internal_force(eta)

    force_scale = np.linalg.norm(projected_force(0.0))
    for k, name in enumerate(prom.shape_names):
        unit = step * np.eye(prom.n_parameters)[k]
        central = (8 * (projected_force(unit) - projected_force(-unit))
                   - (projected_force(2 * unit) - projected_force(-2 * unit))) / (12 * step)
        # z_head only moves the clamped head, where no basis vector deforms: both sides are zero.
        reference = max(np.linalg.norm(central), 1e-9 * force_scale)
        assert np.linalg.norm(derivative[k] - central) < 1e-5 * reference, name


def max_relative_error(actual, expected) -> float:
    """max |actual - expected| / max |expected|."""
    return float(np.max(np.abs(np.asarray(actual) - expected)) / np.max(np.abs(expected)))


def assert_batch_matches_single_runs(prom, scene, xis, amplitudes, batch):
    """Each design of ``batch`` (``simulate_batch`` with sensitivities and the amplitude's) as ``simulate_reduced``
    gives it alone, to 1e-12 relative in distance, tail amplitude and gradient."""
    from aquarom_fenics.dynamics.reduced_dynamics import simulate_reduced

    assert batch.completed.all() and not batch.alone.any()
    for b, xi in enumerate(xis):
        single = simulate_reduced(prom, scene, xi, sensitivities=True, amplitude=amplitudes[b],
                                  amplitude_sensitivity=True)
        assert max_relative_error(batch.distance[b], single.distance) < 1e-12
        assert max_relative_error(batch.tail_amplitude[b], single.tail_amplitude) < 1e-12
        assert max_relative_error(batch.distance_gradient[b], single.distance_gradient) < 1e-12
        assert batch.summary(b)["stop_reason"] == "completed"
