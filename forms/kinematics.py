"""Kinematics of the shape-varied, deformed body on the nominal mesh (SPEC §5).

All quantities are pulled back to the mesh the forms are integrated on: ``shape_displacement``
is u_ξ = U ξ (zero when the design is meshed directly), ``displacement`` is the elastic u.
"""
import ufl


def shape_gradient(shape_displacement):
    """F_1 = I + ∇u_ξ: nominal → shape-varied configuration."""
    return ufl.Identity(3) + ufl.grad(shape_displacement)


def total_gradient(displacement, shape_displacement):
    """F = I + ∇u_ξ + ∇u: nominal → deformed configuration."""
    return ufl.Identity(3) + ufl.grad(shape_displacement) + ufl.grad(displacement)


def relative_gradient(displacement, shape_displacement):
    """F_2 = F F_1⁻¹: shape-varied → deformed configuration."""
    return total_gradient(displacement, shape_displacement) * ufl.inv(shape_gradient(shape_displacement))


def green_lagrange_strain(displacement, shape_displacement):
    """E = ½ (F_2ᵀ F_2 - I), the strain measured from the shape-varied configuration."""
    deformation = relative_gradient(displacement, shape_displacement)
    return 0.5 * (deformation.T * deformation - ufl.Identity(3))


def volume_ratio(shape_displacement):
    """dV_ξ / dV_0 = det F_1."""
    return ufl.det(shape_gradient(shape_displacement))
