"""Mesh recipes and shipped meshes (package data of ``aquarom_fenics.meshes``).

``block.toml`` is the recipe of the reference block of SPEC §3 (levels, element sizes, gmsh
options); ``fish.toml`` the recipe of the shipped fish, whose meshes ``fish_l1.msh`` …
``fish_l4.msh`` are shipped (``scripts/fish_meshes.py`` regenerates them); ``*.inp`` / ``*.msh``
files are meshes scenes can name with ``[mesh] file``. The generated block meshes are cached in
``cache/`` below this folder (not tracked).
"""
