"""Calibration of scene parameters against a measured swim (issue 52): the reduced model's parameter
sensitivities (``parameters``)."""
