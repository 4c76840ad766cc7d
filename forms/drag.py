"""Form drag on the skin (SPEC §5): f_drag = g(ξ) v_x², v_x the head's forward velocity.

Per facet of the shape-varied body at rest: C_d = 2 c_D (n_ξ·e_x)², force -½ ρ_w C_d A_ξ v_x² e_x,
with c_D = ``[fluid] drag_factor`` (1 by default) passed in as fluid_density = c_D ρ_w.
With Nanson's formula the area-weighted normal is a = n_ξ dA_ξ / dA_0 = det F_1 F_1⁻ᵀ N, so
C_d dA_ξ = 2 (a·e_x)² / |a| dA_0.
"""
import ufl

from .kinematics import shape_gradient


def drag_direction_form(test, shape_gradient_field, fluid_density, mesh):
    """g_i = -∫_skin ½ ρ_w C_d φ_i·e_x dA_ξ = -∫_skin c_D ρ_w (a·e_x)² / |a| φ_i·e_x dA_0  [kg/m]
    (``fluid_density`` = c_D ρ_w)."""
    normal = ufl.FacetNormal(mesh)
    deformation = shape_gradient(shape_gradient_field)
    area_normal = ufl.det(deformation) * ufl.inv(deformation).T * normal
    drag_coefficient_area = area_normal[0] ** 2 / ufl.sqrt(ufl.inner(area_normal, area_normal))
    return -fluid_density * drag_coefficient_area * test[0] * ufl.ds
