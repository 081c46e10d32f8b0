"""Coefficients of the fitted curvature model (meshshade.kernels.fitted_curvature, docs/physics.md §14): the table
``data/fitted_curvature.csv``.

Written by ``tools/tables/fit_curvature_model.py`` from the exact-shape Monte Carlo training set
``tools/tables/data/curvature_training.csv``. The file's header records the generator and the sha256 of its source,
the training set with its sha256 and its own header, the train/held-out split, the command, and the meshshade
version, commit and date of the fit (tests/kernels/test_runtime_tables.py checks the hashes); read once, at import.
FEATURES names the features in the order of fitted_curvature.FEATURES, COEF their coefficients theta_j;
ERRORS holds the mean |R / R_mc - 1| per ring of the curvature factor (fitted model, first-order kernel (soft),
plane) on the training and held-out sets, split by the validity measure nu of docs/physics.md eq. (55).
"""
import json

from meshshade.kernels.table_files import floats, read_table

HEADER, _columns = read_table("fitted_curvature.csv")
#: theta_j, in the order of fitted_curvature.FEATURES
FEATURES = tuple(_columns["feature"])
COEF = floats(_columns["coef"])
#: mean |R / R_mc - 1| per ring of the curvature factor: fitted model, first-order kernel (soft), plane;
#: split by the validity measure nu of docs/physics.md eq. (55)
ERRORS = json.loads(HEADER["errors"])
del _columns
