"""Time integration shared by every model, FOM runs and reduced runs with sensitivities."""
