"""Consistent mass of the shape-varied body (SPEC §5)."""
import ufl

from .kinematics import volume_ratio


def mass_density(shape_gradient_field, density):
    """ρ det F_1 [kg/m³ of the nominal body]: the mass per nominal volume of the shape-varied body."""
    return density * volume_ratio(shape_gradient_field)


def mass_form(trial, test, shape_gradient_field, density):
    """M_ij = ∫ ρ φ_i·φ_j dV_ξ = ∫ ρ det F_1 φ_i·φ_j dV_0  [kg]."""
    return mass_density(shape_gradient_field, density) * ufl.inner(trial, test) * ufl.dx


def mass_moment_x(test, shape_gradient_field, density):
    """m_i = ∫ ρ φ_i·e_x dV_ξ; the centre-of-mass x-displacement is m·u / ∫ ρ dV_ξ."""
    return mass_density(shape_gradient_field, density) * test[0] * ufl.dx


def mass_moment_y(test, shape_gradient_field, density):
    """m_i = ∫ ρ φ_i·e_y dV_ξ; the centre-of-mass y-displacement is m·u / ∫ ρ dV_ξ."""
    return mass_density(shape_gradient_field, density) * test[1] * ufl.dx


def total_mass(shape_gradient_field, density, mesh):
    """∫ ρ dV_ξ  [kg]."""
    return mass_density(shape_gradient_field, density) * ufl.dx(domain=mesh)
