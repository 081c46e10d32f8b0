"""``meshshade bench``: its one-line help and its arguments (what it does: :mod:`meshshade.cli.bench`)."""
from __future__ import annotations

import argparse

from meshshade.cli.arguments.common import add_cluster_args, add_deprecated_alias, integer

HELP = "accuracy vs time of every model and knob against exact or Monte Carlo references"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", required=True, metavar="DIR",
                   help="output folder (created): accuracy_vs_time.csv, pareto.png, table.md, metadata.json")
    p.add_argument("--quick", action="store_true",
                   help="fewer scenes and knob values, coarser meshes, fewer photons (under 3 min on 2 idle cores)")
    p.add_argument("--seed", type=integer(0), default=0, help="seed of every Monte Carlo run (default 0)")
    p.add_argument("--scenes", metavar="LIST", help="comma list of scene names (default: the mode's set)")
    p.add_argument("--models", metavar="LIST", help="comma list of models (default: every model of the bake)")
    p.add_argument("--source-model", default="point", choices=["point", "beam"],
                   help="the bakes' source model (default point); scenes with a Monte Carlo reference also get rows "
                        "with the other one (knob source_model)")
    add_deprecated_alias(p, "--near-field", "--source-model", choices=["point", "beam"])
    p.add_argument("--mc-photons", type=integer(16), default=None, metavar="N",
                   help="photons of each Monte Carlo reference (default 1000000 quick, 4000000 full)")
    add_cluster_args(p)   # the references are split on Dask; every timed run stays in this process
