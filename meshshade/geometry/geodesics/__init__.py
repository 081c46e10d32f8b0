"""Geodesic neighbourhoods: exact polyhedral windows (``neighbourhoods``) and the fast curvature-corrected arc
(``arc``); both return CSR ``Neighbourhoods``."""
