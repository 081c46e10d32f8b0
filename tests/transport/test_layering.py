"""Import layering of the transport and output packages: meshshade imports at module top level only, and the
dependency graph kernels <- geometry <- raycast <- light <- transport <- output <- bench/cli has no way back."""
import ast
from pathlib import Path

import pytest

import meshshade

ROOT = Path(meshshade.__file__).parent
#: packages a module of each package must not import (the layers above it)
FORBIDDEN = {"transport": ("meshshade.output", "meshshade.bench", "meshshade.cli"),
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
