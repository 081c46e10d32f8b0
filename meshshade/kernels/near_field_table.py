"""Fitted beam sources of the near-field model (meshshade.kernels.near_field): the table ``data/near_field.csv``.

Written by ``tools/tables/make_near_field_table.py``: for each medium of the grid, the exact half-space Monte Carlo
(pencil beam, all orders) minus exact single scattering, fitted by d'Eon dipoles at fixed depths on the beam. The
file's header records the generator and the sha256 of its source, the command, photons, seeds and grid, and the
meshshade version, commit and date of the run (tests/kernels/test_runtime_tables.py checks the hash); read once,
at import. WEIGHTS[i, j, k] are the source strengths at DEPTHS (optical units, 7 significant digits) for
X_NODES[i] = log10(1 - alpha'), ETA_NODES[j], G_NODES[k]; FIT_ERROR[i, j, k] is the fit's largest |relative error|
against its Monte Carlo rings (those with stderr < 5 %).
"""
import numpy as np

from meshshade.kernels.table_files import floats, grid_shape, read_table

HEADER, _columns = read_table("near_field.csv")
X_NODES = floats(HEADER["x_nodes"])
ETA_NODES = floats(HEADER["eta_nodes"])
G_NODES = floats(HEADER["g_nodes"])
DEPTHS = floats(HEADER["depths"])
_shape = grid_shape(_columns, {"x": X_NODES, "eta": ETA_NODES, "g": G_NODES})
WEIGHTS = np.stack([floats(_columns[f"weight({float(t)!r})"]) for t in DEPTHS], axis=-1).reshape(*_shape, len(DEPTHS))
FIT_ERROR = floats(_columns["fit_error"]).reshape(_shape)
del _columns, _shape
