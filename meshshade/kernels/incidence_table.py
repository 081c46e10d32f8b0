"""How the half-space's total diffuse reflectance grows towards grazing incidence, from exact transport
(meshshade.kernels.near_field.incidence_gain, docs/physics.md eq. (86)): the table ``data/incidence.csv``.

Written by ``tools/tables/make_incidence_table.py`` from the exact half-space Monte Carlo per medium and angle. The
file's header records the generator and the sha256 of its source, the near-field table its eq. (81) gains came from
(with its sha256), the command, photons, seeds and grid, and the meshshade version, commit and date of the run
(tests/kernels/test_runtime_tables.py checks the hashes); read once, at import.
RHO[i, j, k, a] = (T_MC(theta_a) / T_MC(0) - 1) / (W_81(theta_a) - 1) for X_NODES[i] = log10(1 - alpha'),
ETA_NODES[j], G_NODES[k] and the incidence angles ANGLES[a] (degrees, outside); GAIN = T_MC(theta) / T_MC(0)
and GAIN_STDERR its standard error (independent-run bound).
"""
from meshshade.kernels.table_files import floats, grid_shape, read_table

HEADER, _columns = read_table("incidence.csv")
X_NODES = floats(HEADER["x_nodes"])
ETA_NODES = floats(HEADER["eta_nodes"])
G_NODES = floats(HEADER["g_nodes"])
ANGLES = floats(HEADER["angles_deg"])
_shape = grid_shape(_columns, {"x": X_NODES, "eta": ETA_NODES, "g": G_NODES, "angle_deg": ANGLES})
RHO = floats(_columns["rho"]).reshape(_shape)
GAIN = floats(_columns["gain"]).reshape(_shape)
GAIN_STDERR = floats(_columns["gain_stderr"]).reshape(_shape)
del _columns, _shape
