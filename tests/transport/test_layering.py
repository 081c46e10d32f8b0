"""Import layering of the transports and the output: meshshade imports at module top level only, and the
dependency graph kernels <- geometry <- raycast <- light <- (volume | surface) <- transport <- output <- bench/cli
has no way back: the two transports know neither each other nor the bake that chooses between them."""
import ast
from pathlib import Path

import pytest

import meshshade

ROOT = Path(meshshade.__file__).parent
#: packages a module of each package must not import (the layers above it)
FORBIDDEN = {"volume": ("meshshade.surface", "meshshade.transport", "meshshade.output", "meshshade.bench",
                        "meshshade.cli"),
             "surface": ("meshshade.volume", "meshshade.transport", "meshshade.output", "meshshade.bench",
                         "meshshade.cli"),
             "transport": ("meshshade.output", "meshshade.bench", "meshshade.cli"),
             "output": ("meshshade.bench", "meshshade.cli")}


def _modules(package):
    return sorted((ROOT / package).glob("*.py"))


def _imports(tree):
    """(module name, at top level) of every import of the module."""
    top = {id(n) for n in tree.body}
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                yield a.name, id(node) in top
        elif isinstance(node, ast.ImportFrom) and node.module:
            yield node.module, id(node) in top


@pytest.mark.parametrize("path", [p for pkg in FORBIDDEN for p in _modules(pkg)],
                         ids=lambda p: f"{p.parent.name}/{p.name}")
def test_meshshade_imports_are_top_level_and_go_down_the_layers(path):
    tree = ast.parse(path.read_text())
    for name, top in _imports(tree):
        if name == "meshshade" or name.startswith("meshshade."):
            assert top, f"{path.name}: function-level import of {name}"
            assert not name.startswith(FORBIDDEN[path.parent.name]), f"{path.name} imports {name} (a higher layer)"
