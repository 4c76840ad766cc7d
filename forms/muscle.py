"""Muscle energy (SPEC §5): a > 0 contracts the fibres m = e_x.

Π_act = Σ_j ½ k a_j(t) ∫_muscle_j |F_2 m|² dV_ξ,  f_act = -∂Π_act/∂u.
"""
import ufl

from .kinematics import relative_gradient, total_gradient, volume_ratio

FIBRE = ufl.as_vector((1.0, 0.0, 0.0))


def muscle_energy_density(displacement, shape_gradient_field, stiffness, nominal_volume=False):
    """½ k |F_2 m|² det F_1 per nominal volume [J/m³] at unit activation (quadratic in u).

    With ``nominal_volume`` the source's variant ½ k |F m|².
    """
    if nominal_volume:
        stretch = total_gradient(displacement, shape_gradient_field) * FIBRE
        volume = 1.0
    else:
        stretch = relative_gradient(displacement, shape_gradient_field) * FIBRE
        volume = volume_ratio(shape_gradient_field)
    return 0.5 * stiffness * ufl.inner(stretch, stretch) * volume


def muscle_energy(displacement, shape_gradient_field, stiffness, activations, muscle_measures,
                  nominal_volume=False):
    """Σ_j ½ k a_j ∫_muscle_j |F_2 m|² det F_1 dV_0  [J].

    ``activations`` a_j and ``muscle_measures`` dx_j (the measure of muscle j's cells) are paired.
    With ``nominal_volume`` the source's variant Σ_j ½ k a_j ∫_muscle_j |F m|² dV_0 is used.
    """
    density = muscle_energy_density(displacement, shape_gradient_field, stiffness, nominal_volume)
    return sum(a * density * dx for a, dx in zip(activations, muscle_measures))
