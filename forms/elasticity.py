"""Saint Venant-Kirchhoff strain energy of the shape-varied body (SPEC §5)."""
import ufl

from .kinematics import green_lagrange_strain, volume_ratio


def lame_parameters(young_modulus, poisson_ratio):
    """λ = E ν / ((1 + ν)(1 - 2ν)), μ = E / (2 (1 + ν))  [Pa]."""
    lam = young_modulus * poisson_ratio / ((1 + poisson_ratio) * (1 - 2 * poisson_ratio))
    mu = young_modulus / (2 * (1 + poisson_ratio))
    return lam, mu


def svk_energy_density(strain, young_modulus, poisson_ratio):
    """ψ(E) = ½ λ (tr E)² + μ E:E  [J/m³]."""
    lam, mu = lame_parameters(young_modulus, poisson_ratio)
    return 0.5 * lam * ufl.tr(strain) ** 2 + mu * ufl.inner(strain, strain)


def strain_energy(displacement, shape_gradient_field, young_modulus, poisson_ratio):
    """Π = ∫ ψ(E) dV_ξ = ∫ ψ(E) det F_1 dV_0  [J]; f_int = ∂Π/∂u."""
    strain = green_lagrange_strain(displacement, shape_gradient_field)
    density = svk_energy_density(strain, young_modulus, poisson_ratio)
    return density * volume_ratio(shape_gradient_field) * ufl.dx
