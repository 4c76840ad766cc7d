"""AquaROM-FEniCSx: shape optimisation of soft swimmers with parametric reduced-order models."""

__version__ = "0.1.0"
