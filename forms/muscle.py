"""Muscle energy (SPEC §5): a > 0 contracts the fibres m_j (default m = e_x, the body axis).

Π_act = Σ_j ½ k a_j(t) ∫_muscle_j |F_2 m_j|² dV_ξ,  f_act = -∂Π_act/∂u.
"""
import ufl

from .kinematics import relative_gradient, total_gradient, volume_ratio

AXIAL = (1.0, 0.0, 0.0)
"""The default fibre direction m = e_x."""


def muscle_energy_density(displacement, shape_gradient_field, stiffness, nominal_volume=False, fibre=AXIAL):
    """½ k |F_2 m|² det F_1 per nominal volume [J/m³] at unit activation (quadratic in u), m = ``fibre``
    (a unit vector of the nominal body).

    With ``nominal_volume`` the source's variant ½ k |F m|².
    """
    stretch, volume = muscle_stretch(displacement, shape_gradient_field, nominal_volume, fibre)
    return 0.5 * stiffness * ufl.inner(stretch, stretch) * volume


def muscle_stretch(displacement, shape_gradient_field, nominal_volume=False, fibre=AXIAL):
    """(s, v) of the density ψ = ½ k |s|² v: the stretch s = F_2 m (affine in u) and the volume ratio v = det F_1;
    with ``nominal_volume`` s = F m and v = 1."""
    fibre = ufl.as_vector(tuple(float(component) for component in fibre))
    if nominal_volume:
        return total_gradient(displacement, shape_gradient_field) * fibre, 1.0
    return relative_gradient(displacement, shape_gradient_field) * fibre, volume_ratio(shape_gradient_field)


def muscle_energy(displacement, shape_gradient_field, stiffness, activations, muscle_measures,
                  nominal_volume=False, fibres=None):
    """Σ_j ½ k a_j ∫_muscle_j |F_2 m_j|² det F_1 dV_0  [J].

    ``activations`` a_j, ``muscle_measures`` dx_j (the measure of muscle j's cells) and ``fibres`` m_j
    (default: all e_x) are paired. With ``nominal_volume`` the source's variant
    Σ_j ½ k a_j ∫_muscle_j |F m_j|² dV_0 is used.
    """
    fibres = [AXIAL] * len(activations) if fibres is None else [tuple(fibre) for fibre in fibres]
    densities = {fibre: muscle_energy_density(displacement, shape_gradient_field, stiffness, nominal_volume, fibre)
                 for fibre in dict.fromkeys(fibres)}       # one density per direction (all muscles share e_x)
    return sum(a * densities[fibre] * dx for a, dx, fibre in zip(activations, muscle_measures, fibres))
