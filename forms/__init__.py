"""The physics of the swimmer as UFL forms, written once and shared by the FOM and the PROM."""
