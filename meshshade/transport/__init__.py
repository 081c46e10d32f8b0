"""Transport: integrate a diffusion kernel over geodesic neighbourhoods of the light's entry samples.

``bake`` (bake.py) is the entry point; ``zones`` decides how each sample's pairs are found, ``auto`` which kernel
and geodesics each sample needs, ``clusters`` shares far-zone geodesics between samples, ``farfield`` sums the
far tail of flat surroundings with a bounded Taylor expansion.
"""
