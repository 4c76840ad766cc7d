"""Strain energy of the shape-varied body (SPEC §5): Saint Venant-Kirchhoff, or compressible
Neo-Hookean with the same small-strain Lamé moduli (``[material] law``)."""
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


def neo_hookean_energy_density(strain, young_modulus, poisson_ratio):
    """ψ = μ/2 (I₁ - 3) - μ ln J + λ/2 (ln J)²  [J/m³] of the compressible Neo-Hookean law, written
    with C = I + 2E: I₁ - 3 = 2 tr E and ln J = ½ ln det(I + 2E). Its expansion at E = 0 is
    μ E:E + ½ λ (tr E)² + O(|E|³), the SVK density with the same λ, μ."""
    lam, mu = lame_parameters(young_modulus, poisson_ratio)
    log_volume = 0.5 * ufl.ln(ufl.det(ufl.Identity(3) + 2 * strain))
    return mu * ufl.tr(strain) - mu * log_volume + 0.5 * lam * log_volume ** 2


ENERGY_DENSITIES = {"svk": svk_energy_density, "neo-hookean": neo_hookean_energy_density}
"""ψ(E, E_young, ν) of each ``[material] law``."""


def energy_density(law, strain, young_modulus, poisson_ratio):
    """ψ(E) of the ``law`` ("svk" or "neo-hookean")  [J/m³]."""
    return ENERGY_DENSITIES[law](strain, young_modulus, poisson_ratio)


def small_strain_energy_density(law, strain, young_modulus, poisson_ratio):
    """ψ₂(E) = ½ E:ℂ₀:E, the law's second-order expansion at E = 0 (ℂ₀ = ∂²ψ/∂E² at 0)  [J/m³]:
    the SVK density for both laws (their λ, μ are the same); exact for SVK, whose ψ is quadratic in E."""
    if law not in ENERGY_DENSITIES:
        raise ValueError(f"unknown material law {law!r}")
    return svk_energy_density(strain, young_modulus, poisson_ratio)


def strain_energy(displacement, shape_gradient_field, young_modulus, poisson_ratio, law="svk"):
    """Π = ∫ ψ(E) dV_ξ = ∫ ψ(E) det F_1 dV_0  [J]; f_int = ∂Π/∂u."""
    strain = green_lagrange_strain(displacement, shape_gradient_field)
    density = energy_density(law, strain, young_modulus, poisson_ratio)
    return density * volume_ratio(shape_gradient_field) * ufl.dx
