"""Mesh recipes and shipped meshes (package data of ``aquarom_fenics.meshes``).

``block.toml`` is the recipe of the reference block of SPEC §3 (levels, element sizes, gmsh
options); ``*.inp`` / ``*.msh`` files are meshes scenes can name with ``[mesh] file``. The
generated block meshes are cached in ``cache/`` below this folder (not tracked).
"""
