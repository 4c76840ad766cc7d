"""The shipped scenes (package data of ``aquarom_fenics.scenes``): ``aquarom simulate so1`` finds
``so1.toml`` here."""
