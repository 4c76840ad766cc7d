"""A design direction δξ as coefficients of a pulled-back FOM's forms (``FullOrderModel.shape_direction``)."""
from __future__ import annotations

from aquarom_fenics.fem import dolfinx_adapter as fx


class ShapeDirection:
    """A design direction δξ as the coefficients the forms are differentiated along.

    δu_ξ = U δξ at the displacement nodes (the skin form) and ∇δu_ξ = ∇U δξ, exact, at the points
    of each quadrature rule (the volume forms), on the model's nominal mesh.
    """

    def __init__(self, fom: FullOrderModel, name: str):
        self.fom = fom
        self.nodal = fx.new_function(fom.space, f"{name}_nodal")
        self.gradients = {family: fx.new_function(gradient.function_space, f"{name}_{family}")
                          for family, gradient in fom.shape_gradients.items()}

    def pairs(self):
        """(shape coefficient, its variation) for every representation of u_ξ."""
        fom = self.fom
        return [(fom.shape_displacement, self.nodal)] + [(fom.shape_gradients[family], self.gradients[family])
                                                        for family in self.gradients]

    def set_parameter(self, k: int) -> None:
        """δξ = e_k: δu_ξ = U_k."""
        fom = self.fom
        fx.set_owned_values(self.nodal, fom.owned_values(fom.fish.shape_matrix[:, k].reshape(-1, 3)))
        for family, function in self.gradients.items():
            fx.set_quadrature_values(function, fom.shape_direction_gradient(family, k))
