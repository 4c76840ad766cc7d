"""Consistent mass of the shape-varied body (SPEC §5)."""
import ufl

from .kinematics import volume_ratio


def mass_form(trial, test, shape_gradient_field, density):
    """M_ij = ∫ ρ φ_i·φ_j dV_ξ = ∫ ρ φ_i·φ_j det F_1 dV_0  [kg]."""
    return density * ufl.inner(trial, test) * volume_ratio(shape_gradient_field) * ufl.dx


def mass_moment_x(test, shape_gradient_field, density):
    """m_i = ∫ ρ φ_i·e_x dV_ξ; the centre-of-mass x-displacement is m·u / ∫ ρ dV_ξ."""
    return density * test[0] * volume_ratio(shape_gradient_field) * ufl.dx


def total_mass(shape_gradient_field, density, mesh):
    """∫ ρ dV_ξ  [kg]."""
    return density * volume_ratio(shape_gradient_field) * ufl.dx(domain=mesh)
