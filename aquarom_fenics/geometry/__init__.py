"""Geometry: meshes, regions and spine nodes, shape variations, the fish of a scene."""
