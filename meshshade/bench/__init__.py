"""Accuracy versus time: scenes as data, a plan of runs, the runner, exact and Monte Carlo references, reports."""
