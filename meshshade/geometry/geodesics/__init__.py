"""Geodesic neighbourhoods: exact polyhedral windows (``neighbourhoods``) and the approximate curvature-corrected arcs
(``arc``); both return CSR ``Neighbourhoods``."""
