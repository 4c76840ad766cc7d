"""Checks against the FOM: Taylor tests, comparisons, mesh convergence, energy balance."""
