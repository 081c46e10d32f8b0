"""The CLI's structure: two modules per subcommand (its arguments, light; what it does), shared options, no import
cycles, files written through io."""
from __future__ import annotations

import ast
import re
import subprocess
import sys
from pathlib import Path

import pytest

from meshshade.cli import arguments, bake, batch, bench, blender, check, compare, demo, materials, mc, profile, render
from meshshade.cli.main import COMMANDS, build_parser, load_command, main
from meshshade.errors import OutputError
from meshshade.geometry.procedural import icosphere
from meshshade import io
from meshshade.io import write_ply
from meshshade.transport import MODELS

ROOT = Path(__file__).resolve().parents[2]
CLI = ROOT / "meshshade" / "cli"
BENCH = ROOT / "meshshade" / "bench"
MODULES = {"bake": bake, "batch": batch, "blender": blender, "bench": bench, "check": check, "compare": compare,
           "demo": demo, "materials": materials, "mc": mc, "profile": profile, "render": render}


def test_commands_are_the_subcommand_modules():
    """Each command: HELP and add_arguments in meshshade.cli.arguments.<name>, run_<name> in meshshade.cli.<name>
    (what load_command imports), and no module of either kind without a command."""
    assert set(COMMANDS) == set(MODULES)
    assert {p.stem for p in (CLI / "arguments").glob("*.py")} - {"__init__", "common"} == set(MODULES)
    for name, module in MODULES.items():
        arguments_module = COMMANDS[name]
        assert arguments_module is getattr(arguments, name) and arguments_module.__name__.endswith(f".{name}")
        assert callable(arguments_module.add_arguments)
        assert isinstance(arguments_module.HELP, str) and "\n" not in arguments_module.HELP
        run, io_package = load_command(name)
        assert run is getattr(module, f"run_{name}") and io_package is io


def _choices(parser, command, dest):
    sub = next(a for a in parser._actions if a.dest == "command").choices[command]
    return next(a for a in sub._actions if a.dest == dest).choices


def test_model_choices_are_the_transport_models():
    parser = build_parser()
    for command in ("bake", "render"):
        assert tuple(_choices(parser, command, "model")) == tuple(MODELS)


def _meshshade_imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text())
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("meshshade"):
            found |= {node.module} | {f"{node.module}.{a.name}" for a in node.names}
        elif isinstance(node, ast.Import):
            found |= {a.name for a in node.names if a.name.startswith("meshshade")}
    return found


@pytest.mark.parametrize("path", sorted(CLI.rglob("*.py")), ids=lambda p: p.relative_to(CLI).as_posix())
def test_subcommand_modules_do_not_import_main(path):
    """Only __main__.py imports cli.main; the subcommand, argument and option modules never do (no import
    cycle)."""
    if path.relative_to(CLI).as_posix() != "__main__.py":
        assert "meshshade.cli.main" not in _meshshade_imports(path)


@pytest.mark.parametrize("path", sorted(CLI.rglob("*.py")) + sorted(BENCH.glob("*.py")),
                         ids=lambda p: f"{p.parent.name}/{p.name}")
def test_meshshade_imports_at_module_top_level(path):
    tree = ast.parse(path.read_text())
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            for inner in ast.walk(node):
                if isinstance(inner, ast.ImportFrom) and (inner.module or "").startswith("meshshade"):
                    pytest.fail(f"{path.name}:{inner.lineno}: function-level import of {inner.module}")
                if isinstance(inner, ast.Import) and any(a.name.startswith("meshshade") for a in inner.names):
                    pytest.fail(f"{path.name}:{inner.lineno}: function-level import")
    assert "__import__" not in path.read_text()


WRITES = re.compile(r"\bopen\(|\.write_text\(|\.write_bytes\(|\.mkdir\(|savefig\(|np\.save")


@pytest.mark.parametrize("path", sorted(CLI.rglob("*.py")) + sorted(BENCH.glob("*.py")),
                         ids=lambda p: f"{p.parent.name}/{p.name}")
def test_files_are_written_only_through_io(path):
    """Files and directories only through meshshade.io (io.output_dir for the output folder)."""
    hits = [(i, line) for i, line in enumerate(path.read_text().splitlines(), 1) if WRITES.search(line)]
    assert hits == []


def test_output_dir_creates_parents_and_refuses_files(tmp_path):
    out = io.output_dir(tmp_path / "a" / "b")
    assert out.is_dir() and io.output_dir(out) == out
    f = tmp_path / "file"
    f.write_text("x")
    with pytest.raises(OutputError, match="--out .* exists and is not a directory"):
        io.output_dir(f)


@pytest.mark.parametrize("command", ["compare", "demo"])
def test_out_folder_that_is_a_file_is_one_line_exit_2(tmp_path, capsys, command):
    V, F = icosphere(10.0, 1)
    mesh = tmp_path / "s.ply"
    write_ply(mesh, V, F)
    f = tmp_path / "file"
    f.write_text("x")
    argv = ["demo", "--out", str(f)] if command == "demo" else [
        "compare", str(mesh), "--material", "skin1", "--light", "directional:0,0,-1", "--out", str(f), "-q"]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("meshshade: error:") and "not a directory" in err[0]
    assert f.read_text() == "x"


def test_python_m_meshshade_cli_help():
    res = subprocess.run([sys.executable, "-m", "meshshade.cli", "--help"], capture_output=True, text=True,
                         cwd=str(ROOT), timeout=120)
    assert res.returncode == 0, res.stderr
    assert all(name in res.stdout for name in COMMANDS)
