"""Finite elements: the dolfinx adapter, the full-order model and point-wise form sampling."""
