"""``meshshade blender``: the add-on file Blender's preferences install (no bpy needed to write it)."""
from __future__ import annotations

import ast
import pytest

import meshshade.blender
from meshshade.cli.main import main


def test_writes_a_legacy_addon_file_with_a_literal_bl_info(tmp_path, capsys):
    out = tmp_path / "meshshade_addon.py"
    assert main(["blender", str(out)]) == 0
    tree = ast.parse(out.read_text())
    assigns = {n.targets[0].id: n.value for n in tree.body if isinstance(n, ast.Assign)}
    info = ast.literal_eval(assigns["bl_info"])     # Blender reads bl_info without running the file
    assert info == meshshade.blender.bl_info and info["blender"] >= (4, 2, 0)
    funcs = {n.name for n in tree.body if isinstance(n, ast.FunctionDef)}
    assert {"register", "unregister"} <= funcs
    assert "Install from Disk" in capsys.readouterr().out


def test_refuses_a_name_that_is_not_python(tmp_path, capsys):
    assert main(["blender", str(tmp_path / "addon.txt")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("meshshade: error:") and err.count("\n") == 1
    assert not (tmp_path / "addon.txt").exists()


def test_register_outside_blender_says_where_it_runs():
    try:
        import bpy  # noqa: F401
    except ImportError:
        pass
    else:
        pytest.skip("bpy is importable here: register() is the real add-on (tests/blender/test_addon.py)")
    with pytest.raises(ImportError, match="run inside Blender.*docs/blender.md"):
        meshshade.blender.register()
