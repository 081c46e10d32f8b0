"""Mesh geometry: the validated ``Mesh`` container, topology repair, curvature, procedural shapes.

Modules are imported explicitly (``from meshshade.geometry.mesh import Mesh``); importing this package has no
side effects.
"""
