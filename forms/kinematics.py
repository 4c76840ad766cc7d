"""Kinematics of the shape-varied, deformed body on the nominal mesh (SPEC §5).

All quantities are pulled back to the mesh the forms are integrated on: ``shape_gradient_field``
is ∇u_ξ, the gradient of the design's shape displacement u_ξ = U ξ (zero when the design is
meshed directly; the FOM passes the exact ∇U ξ at the quadrature points), ``displacement`` is
the elastic u.
"""
import ufl


def shape_gradient(shape_gradient_field):
    """F_1 = I + ∇u_ξ: nominal → shape-varied configuration."""
    return ufl.Identity(3) + shape_gradient_field


def total_gradient(displacement, shape_gradient_field):
    """F = I + ∇u_ξ + ∇u: nominal → deformed configuration."""
    return ufl.Identity(3) + shape_gradient_field + ufl.grad(displacement)


def relative_gradient(displacement, shape_gradient_field):
    """F_2 = F F_1⁻¹: shape-varied → deformed configuration."""
    return total_gradient(displacement, shape_gradient_field) * ufl.inv(shape_gradient(shape_gradient_field))


def relative_displacement_gradient(displacement, shape_gradient_field):
    """H = F_2 - I = ∇u F_1⁻¹, since (I + ∇u_ξ) F_1⁻¹ = I."""
    return ufl.grad(displacement) * ufl.inv(shape_gradient(shape_gradient_field))


def green_lagrange_strain(displacement, shape_gradient_field):
    """E = ½ (F_2ᵀ F_2 - I) = ½ (H + Hᵀ + Hᵀ H), the strain measured from the shape-varied configuration.

    Written with H = F_2 - I: F_2ᵀ F_2 - I would cancel to round-off, leaving a relative error of
    about 1e-16 / |H| (1e-5 at the strains of a smooth start's first step, where Newton stalls).
    """
    gradient = relative_displacement_gradient(displacement, shape_gradient_field)
    return 0.5 * (gradient + gradient.T + gradient.T * gradient)


def volume_ratio(shape_gradient_field):
    """dV_ξ / dV_0 = det F_1."""
    return ufl.det(shape_gradient(shape_gradient_field))
