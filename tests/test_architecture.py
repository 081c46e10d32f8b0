"""Architecture lint: the package's layering rules, checked on the AST of every module under meshshade/.

Rules (the issue "One package per stage"):

(a) ``meshshade/kernels/`` imports only numpy, scipy, numba, math (and the stdlib __future__, typing,
    dataclasses, functools) and meshshade.errors / meshshade.kernels.*: kernels are pure array functions;
(b) only the package ``meshshade/io/`` (``meshshade.io`` and its submodules, which also create the output
    directories, ``io.output_dir``) creates, opens, writes, moves or deletes files, and
    ``meshshade/compiled_cache.py``, which places numba's on-disk cache before anything imports numba
    (``meshshade.io`` imports numba);
(c) only ``meshshade/raycast/`` imports embreex or loads a native library (Embree) with ctypes;
(d) no import cycles among meshshade modules (graph of all imports, module- and function-level);
(e) no function-level imports of meshshade modules (they hide the dependency graph);
(f) no module uses another package's private names: an underscore name (``_INV_SAT``, ``_row_at``) or an
    underscore module (``_window_loops``) is imported, or reached as an attribute of an imported module, only
    from within the directory that holds it (``meshshade/io/meshes.py`` may import ``meshshade/io/_reading.py``;
    ``meshshade/transport/x.py`` may not import ``meshshade.kernels.curvature.policies._INV_SAT``): a name shared
    across packages is public, named without the underscore and documented. Exceptions: :data:`PRIVATE_ALLOWED`,
    each with its reason, and an entry that is no longer needed fails too;
(g) a module is imported by a name computed at run time (``importlib.import_module(name)``) only in the functions
    of :data:`LAZY_IMPORTS`, each with its reason and the modules it may import (edges of the import graph like
    any other; rule (e) lets these functions import at function level): the root package's public names on first
    use, and a command's modules once its arguments are parsed (``meshshade --help`` imports no numba);
(h) no function takes more than :data:`MAX_PARAMS` parameters (positional and keyword-only alike; ``self`` and
    ``cls``, ``*args`` and ``**kwargs`` not counted), except numba's compiled loops (decorated with ``njit``,
    ``jit``, ``vectorize``... or passed to one, ``njit(parallel=True)(_walk)``: their interface is numba's, arrays
    and scalars) and the entries of :data:`PARAMS_ALLOWED`, each with its reason. Many values that travel together
    are a small record (a NamedTuple or a dataclass), not a long signature.

The checkers are plain functions of a root directory (the folder that holds the ``meshshade`` package); nothing
is imported or executed. They are themselves tested on a small fake package written to tmp_path with one
planted violation per rule.
"""
from __future__ import annotations

import ast
import sys
from dataclasses import dataclass, field
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "meshshade"

KERNEL_ALLOWED_ROOTS = {"numpy", "scipy", "numba", "math", "__future__", "typing", "dataclasses", "functools"}
#: kernel modules that may also import the standard library's file readers, and why
KERNEL_TABLE_READERS = {
    "meshshade/kernels/table_files.py": ({"csv", "pathlib"}, "reads the kernels' own tables (meshshade/kernels/data/"
                                         "*.csv, shipped with the package) once at import: constants stored as "
                                         "data with their provenance, never a user's file"),
    "meshshade/kernels/fitted_curvature_table.py": ({"json"}, "parses the JSON fields of its table's header"),
}
#: (module, function qualname) allowed to touch files; None: the whole module, or the whole package (the package
#: and every module under it: meshshade.io is the package meshshade/io/)
FILE_IO_ALLOWED = {("meshshade.io", None), ("meshshade.compiled_cache", None), ("meshshade.asset_cache", None)}
#: method names that create, open, write, move or delete files on whatever object they are called
FILE_METHODS = {"open", "write_text", "write_bytes", "mkdir", "touch", "unlink", "savefig", "tofile", "imsave"}
#: Path.rename(target) / Path.replace(target): one positional argument (str.replace needs two)
FILE_METHODS_ONE_ARG = {"rename", "replace"}
FILE_FUNCTIONS = {"open", "io.open", "codecs.open", "os.open", "os.replace", "os.rename", "os.renames", "os.remove",
                  "os.unlink", "os.makedirs", "os.mkdir", "os.rmdir", "os.removedirs", "numpy.save", "numpy.savez",
                  "numpy.savez_compressed", "numpy.savetxt"}
FILE_MODULES = ("shutil.", "tempfile.")
CTYPES_LOADERS = ("ctypes.CDLL", "ctypes.PyDLL", "ctypes.WinDLL", "ctypes.OleDLL", "ctypes.LibraryLoader",
                  "ctypes.cdll", "ctypes.pydll", "ctypes.windll", "ctypes.util.find_library")


def _table_values(module: str, table: str):
    """Resolver of :data:`LAZY_IMPORTS`: the string values of the dict literal ``table`` in ``module``."""
    def resolve(mods) -> set[str]:
        for node in mods[module].tree.body:
            if isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == table for t in node.targets):
                return {v for v in ast.literal_eval(node.value).values() if isinstance(v, str)}
        return set()
    return resolve


def _command_modules(mods) -> set[str]:
    """Resolver of :data:`LAZY_IMPORTS`: ``meshshade.cli.<name>`` for every ``meshshade.cli.arguments.<name>``."""
    prefix = f"{PACKAGE}.cli.arguments."
    names = {m[len(prefix):] for m in mods if m.startswith(prefix) and "." not in m[len(prefix):]}
    return {f"{PACKAGE}.cli.{n}" for n in names if f"{PACKAGE}.cli.{n}" in mods}


#: (g) (module, function) -> (why it imports modules by names computed at run time, the resolver of the modules it
#: may so import: a function of the collected modules)
LAZY_IMPORTS = {
    (PACKAGE, "__getattr__"): ("PEP 562: the public names of `import meshshade` that need numba (Material, ...) "
                               "are imported on first use; the modules of its _LAZY table",
                               _table_values(PACKAGE, "_LAZY")),
    (f"{PACKAGE}.cli.main", "load_command"): ("a command's modules (numpy, numba, scipy: a second) are imported "
                                              "once its arguments are parsed and the signal handling is in place; "
                                              "meshshade.cli.<name> of each meshshade.cli.arguments.<name>",
                                              _command_modules),
    (f"{PACKAGE}.batch.runner", "versions"): ("the versions of the libraries a job's results depend on (numpy, "
                                              "dask...), imported by name when not yet imported: no meshshade module",
                                              lambda mods: set()),
}

#: (importing module's path, the private name it uses, dotted) -> why it may, until its owner removes the entry
PRIVATE_ALLOWED: dict = {}

#: the most parameters a function takes (rule (h))
MAX_PARAMS = 12
#: numba's compilers (under ``numba.``): what they decorate or wrap is a compiled loop, outside rule (h) (``overload``:
#: the function it overloads is compiled into its callers)
COMPILERS = {"njit", "jit", "vectorize", "guvectorize", "cfunc", "stencil", "generated_jit", "overload"}
#: why a public entry point may take more: its options are keyword-only, named at every call
PUBLIC_OPTIONS = "a public entry point whose options are keyword-only (each named at every call, none positional)"
#: (module path, function qualname) -> why it may take more than MAX_PARAMS parameters
PARAMS_ALLOWED = {
    **{(path, f"{cls}.query"): ("the geodesic query: the sources' columns (positions, faces, barycentrics, vertex, "
                                "normals, radius) and keyword-only frame options (d1, d2, k1, k2, progress...), "
                                "named at every call")
       for path, cls in (("meshshade/geometry/geodesics/neighbourhoods.py", "GeodesicNeighbourhoods"),
                         ("meshshade/geometry/geodesics/arc.py", "ArcGeodesicNeighbourhoods"))},
}

@dataclass(frozen=True)
class Violation:
    rule: str
    path: str
    line: int
    message: str

    def __str__(self):
        return f"{self.path}:{self.line}: [{self.rule}] {self.message}"


@dataclass(frozen=True)
class Import:
    """One imported module, absolute (``from pkg import name`` resolved to ``pkg.name`` when that is a module)."""
    target: str
    line: int
    scope: str | None  # qualname of the enclosing function, None at module or class level


@dataclass
class Module:
    name: str
    path: Path
    rel: str
    is_package: bool
    tree: ast.Module
    imports: list[Import] = field(default_factory=list)
    computed_imports: list[Import] = field(default_factory=list)  # import_module(<not a literal>): target ""
    aliases: dict[str, str] = field(default_factory=dict)  # local name -> dotted name (all imports)


# ------------------------------------------------------------------------------------------------------
# collection
# ------------------------------------------------------------------------------------------------------
def collect_modules(root: Path, package: str = PACKAGE) -> dict[str, Module]:
    """Every module of ``root/package`` by dotted name, parsed, with its imports resolved."""
    root = Path(root)
    mods = {}
    for path in sorted((root / package).rglob("*.py")):
        parts = path.relative_to(root).with_suffix("").parts
        is_pkg = parts[-1] == "__init__"
        name = ".".join(parts[:-1] if is_pkg else parts)
        mods[name] = Module(name, path, path.relative_to(root).as_posix(), is_pkg,
                            ast.parse(path.read_text(), filename=str(path)))
    for mod in mods.values():
        _ImportCollector(mod, set(mods)).visit(mod.tree)
    return mods


def _absolute(mod: Module, level: int, module: str | None) -> str:
    """The absolute module of a (possibly relative) ``from`` import."""
    if level == 0:
        return module or ""
    base = mod.name.split(".")
    base = base if mod.is_package else base[:-1]
    base = base[: len(base) - (level - 1)]
    return ".".join(base + ([module] if module else []))


class _Scoped(ast.NodeVisitor):
    """Tracks the qualname of the enclosing function (None outside functions)."""

    def __init__(self):
        self.stack: list[tuple[str, bool]] = []  # (name, is_function)

    @property
    def scope(self) -> str | None:
        if not any(is_fn for _, is_fn in self.stack):
            return None
        return ".".join(name for name, _ in self.stack)

    def _enter(self, node, name, is_fn):
        self.stack.append((name, is_fn))
        self.generic_visit(node)
        self.stack.pop()

    def visit_FunctionDef(self, node):
        self._enter(node, node.name, True)

    visit_AsyncFunctionDef = visit_FunctionDef

    def visit_Lambda(self, node):
        self._enter(node, "<lambda>", True)

    def visit_ClassDef(self, node):
        self._enter(node, node.name, False)


class _ImportCollector(_Scoped):
    def __init__(self, mod: Module, names: set[str]):
        super().__init__()
        self.mod, self.names = mod, names

    def _add(self, target, line):
        self.mod.imports.append(Import(target, line, self.scope))

    def visit_Import(self, node):
        for a in node.names:
            self._add(a.name, node.lineno)
            self.mod.aliases[a.asname or a.name.split(".")[0]] = a.name if a.asname else a.name.split(".")[0]

    def visit_ImportFrom(self, node):
        base = _absolute(self.mod, node.level, node.module)
        targets = []
        for a in node.names:
            sub = f"{base}.{a.name}"
            targets.append(sub if sub in self.names else base)
            self.mod.aliases[a.asname or a.name] = sub
        for target in dict.fromkeys(targets):  # once per statement and module
            self._add(target, node.lineno)

    def visit_Call(self, node):
        # importlib.import_module("x") / __import__("x") with a literal name: an import like any other
        fn = _dotted(node.func, self.mod.aliases)
        if fn in ("importlib.import_module", "__import__") and node.args and isinstance(node.args[0], ast.Constant) \
                and isinstance(node.args[0].value, str):
            self._add(node.args[0].value, node.lineno)
        elif fn in ("importlib.import_module", "__import__"):  # a name computed at run time: rule (g)
            self.mod.computed_imports.append(Import("", node.lineno, self.scope))
        self.generic_visit(node)


def _dotted(node: ast.AST, aliases: dict[str, str]) -> str | None:
    """``a.b.c`` of a Name/Attribute chain with its root resolved through the module's imports."""
    parts = []
    while isinstance(node, ast.Attribute):
        parts.append(node.attr)
        node = node.value
    if not isinstance(node, ast.Name):
        return None
    return ".".join([aliases.get(node.id, node.id), *reversed(parts)])


def _in(name: str, prefix: str) -> bool:
    return name == prefix or name.startswith(prefix + ".")


# ------------------------------------------------------------------------------------------------------
# rules
# ------------------------------------------------------------------------------------------------------
def check_kernel_imports(root: Path, package: str = PACKAGE) -> list[Violation]:
    """(a) kernels import only numerics, meshshade.errors and other kernels."""
    out = []
    for mod in collect_modules(root, package).values():
        if not _in(mod.name, f"{package}.kernels"):
            continue
        for imp in mod.imports:
            root_name = imp.target.split(".")[0]
            ok = (root_name in KERNEL_ALLOWED_ROOTS or _in(imp.target, f"{package}.errors")
                  or _in(imp.target, f"{package}.kernels")
                  or root_name in KERNEL_TABLE_READERS.get(mod.rel, (set(), ""))[0])
            if not ok:
                out.append(Violation("kernels", mod.rel, imp.line, f"kernel module imports {imp.target}"))
    return out


class _CallCollector(_Scoped):
    def __init__(self, mod: Module):
        super().__init__()
        self.mod = mod
        self.calls: list[tuple[ast.Call, str | None]] = []
        # names bound to an OpenImageIO ImageBuf anywhere in the module: their .write() writes a file
        self.imagebufs = {t.id for n in ast.walk(mod.tree) if isinstance(n, ast.Assign)
                          and isinstance(n.value, ast.Call) and (_dotted(n.value.func, mod.aliases) or "")
                          .endswith("ImageBuf") for t in n.targets if isinstance(t, ast.Name)}

    def visit_Call(self, node):
        self.calls.append((node, self.scope))
        self.generic_visit(node)


def _file_call(call: ast.Call, aliases: dict[str, str], imagebufs: set[str]) -> str | None:
    """What a call does to the file system, or None."""
    fn = _dotted(call.func, aliases)
    if fn is not None:
        if fn in FILE_FUNCTIONS or fn.startswith(FILE_MODULES) or "ImageOutput" in fn:
            return f"calls {fn}"
    if isinstance(call.func, ast.Attribute):
        attr, recv = call.func.attr, call.func.value
        if attr in FILE_METHODS:
            return f"calls .{attr}()"
        if attr in FILE_METHODS_ONE_ARG and len(call.args) == 1 and not call.keywords \
                and (_dotted(recv, aliases) or "").split(".")[0] != "dataclasses":
            return f"calls .{attr}(target) (Path.{attr})"
        if attr == "write" and ((isinstance(recv, ast.Name) and recv.id in imagebufs) or (
                isinstance(recv, ast.Call) and (_dotted(recv.func, aliases) or "").endswith("ImageBuf"))):
            return "calls ImageBuf.write()"
    return None


def check_file_io(root: Path, package: str = PACKAGE, allowed=FILE_IO_ALLOWED) -> list[Violation]:
    """(b) only meshshade.io and its submodules (and the allow-listed CLI helper) touch files."""
    out = []
    for mod in collect_modules(root, package).values():
        if any(f is None and _in(mod.name, m) for m, f in allowed):
            continue
        collector = _CallCollector(mod)
        collector.visit(mod.tree)
        for call, scope in collector.calls:
            what = _file_call(call, mod.aliases, collector.imagebufs)
            if what is None:
                continue
            if scope is not None and any(m == mod.name and f is not None and (scope == f or scope.startswith(f + "."))
                                         for m, f in allowed):
                continue
            out.append(Violation("file-io", mod.rel, call.lineno, f"{what} in {scope or '<module>'}"))
    return out


def check_embree_confinement(root: Path, package: str = PACKAGE) -> list[Violation]:
    """(c) embreex and ctypes library loading only in meshshade/raycast/."""
    out = []
    for mod in collect_modules(root, package).values():
        if _in(mod.name, f"{package}.raycast"):
            continue
        for imp in mod.imports:
            if _in(imp.target, "embreex"):
                out.append(Violation("embree", mod.rel, imp.line, f"imports {imp.target} outside raycast/"))
        collector = _CallCollector(mod)
        collector.visit(mod.tree)
        for call, _ in collector.calls:
            fn = _dotted(call.func, mod.aliases) or ""
            if any(_in(fn, loader) for loader in CTYPES_LOADERS):
                out.append(Violation("embree", mod.rel, call.lineno, f"loads a native library ({fn}) outside raycast/"))
    return out


def import_graph(root: Path, package: str = PACKAGE, lazy=LAZY_IMPORTS) -> dict[str, set[str]]:
    """module -> the meshshade modules it imports (module- and function-level, and what the functions of ``lazy``
    import by computed names; no implicit parent packages)."""
    mods = collect_modules(root, package)
    graph = {name: set() for name in mods}
    for mod in mods.values():
        for imp in mod.imports:
            if imp.target in mods and imp.target != mod.name:
                graph[mod.name].add(imp.target)
        for imp in mod.computed_imports:
            if (mod.name, imp.scope) in lazy:
                graph[mod.name] |= {t for t in lazy[mod.name, imp.scope][1](mods) if t in mods and t != mod.name}
    return graph


def strongly_connected_components(graph: dict[str, set[str]]) -> list[list[str]]:
    """Tarjan's algorithm (iterative); every component, each sorted."""
    index, low, on_stack, stack, comps = {}, {}, set(), [], []
    counter = 0
    for start in sorted(graph):
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = counter
        counter += 1
        stack.append(start)
        on_stack.add(start)
        while work:
            node, it = work[-1]
            for nxt in it:
                if nxt not in index:
                    index[nxt] = low[nxt] = counter
                    counter += 1
                    stack.append(nxt)
                    on_stack.add(nxt)
                    work.append((nxt, iter(sorted(graph[nxt]))))
                    break
                if nxt in on_stack:
                    low[node] = min(low[node], index[nxt])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    comp = []
                    while True:
                        top = stack.pop()
                        on_stack.discard(top)
                        comp.append(top)
                        if top == node:
                            break
                    comps.append(sorted(comp))
    return comps


def import_cycles(root: Path, package: str = PACKAGE) -> list[list[str]]:
    """(d) the strongly connected components of more than one module."""
    return sorted(c for c in strongly_connected_components(import_graph(root, package)) if len(c) > 1)


def stage_graph(root: Path, package: str = PACKAGE) -> dict[str, set[str]]:
    """The import graph collapsed to pipeline stages: ``meshshade.<first component>`` (a subpackage such as
    ``meshshade.transport`` or ``meshshade.io``, or a top-level module such as ``meshshade.units``); the root package
    is its own node."""
    def stage(name):
        parts = name.split(".")
        return ".".join(parts[:2])
    graph: dict[str, set[str]] = {}
    for src, targets in import_graph(root, package).items():
        graph.setdefault(stage(src), set()).update(stage(t) for t in targets if stage(t) != stage(src))
    for targets in list(graph.values()):
        for t in targets:
            graph.setdefault(t, set())
    return graph


def stage_cycles(root: Path, package: str = PACKAGE) -> list[list[str]]:
    """(d) at the level of stages: the packages form a DAG (kernels <- geometry <- raycast <- light <- transport
    <- output <- bench/cli), so no stage depends on one that depends on it."""
    return sorted(c for c in strongly_connected_components(stage_graph(root, package)) if len(c) > 1)


def check_function_level_imports(root: Path, package: str = PACKAGE, lazy=LAZY_IMPORTS) -> list[Violation]:
    """(e) meshshade modules are imported at module level only (but in the lazy importers of ``lazy``)."""
    out = []
    for mod in collect_modules(root, package).values():
        for imp in mod.imports:
            if imp.scope is not None and _in(imp.target, package) and (mod.name, imp.scope) not in lazy:
                out.append(Violation("function-import", mod.rel, imp.line, f"imports {imp.target} inside {imp.scope}"))
    return out


def _is_private(name: str) -> bool:
    """``_x`` and ``__x`` are private; ``__x__`` (``__version__``, ``__future__``) is not."""
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def _used_names(mod: Module, package: str):
    """``(line, [component, ...])`` of every dotted meshshade name the module imports (``from a.b import c``:
    ``[meshshade, a, b, c]``; relative imports resolved) or reaches as a private attribute of an imported name
    (``K._OPTS`` after ``from meshshade.montecarlo import loops as K``)."""
    for node in ast.walk(mod.tree):
        if isinstance(node, ast.ImportFrom):
            base = _absolute(mod, node.level, node.module)
            chains = [f"{base}.{a.name}" for a in node.names if a.name != "*"]
        elif isinstance(node, ast.Import):
            chains = [a.name for a in node.names]
        elif isinstance(node, ast.Attribute) and _is_private(node.attr):
            chains = [_dotted(node, mod.aliases) or ""]
        else:
            continue
        for chain in chains:
            parts = chain.split(".")
            if parts[0] == package:
                yield node.lineno, parts


def private_uses(root: Path, package: str = PACKAGE) -> list[Violation]:
    """(f) every use of a private name (or private module) held in another directory than the user's.

    The owner of a private component is the nearest module above it (``meshshade.io`` for ``meshshade.io._reading``,
    ``...policies`` for ``...policies._INV_SAT``, the module for a class's ``_method``); the use is private to a
    package when the owner's file lies in the user's own directory. The message is the private name, dotted up to
    its first private component."""
    mods = collect_modules(root, package)
    out = []
    for mod in mods.values():
        seen = set()
        for line, parts in _used_names(mod, package):
            i = next((i for i, p in enumerate(parts) if i > 0 and _is_private(p)), None)
            if i is None:
                continue
            owner = next((".".join(parts[:j]) for j in range(i, 0, -1) if ".".join(parts[:j]) in mods), None)
            name = ".".join(parts[: i + 1])
            if owner is None or mods[owner].path.parent == mod.path.parent or (line, name) in seen:
                continue
            seen.add((line, name))
            out.append(Violation("private", mod.rel, line, name))
    return out


def check_private_imports(root: Path, package: str = PACKAGE, allowed=PRIVATE_ALLOWED) -> list[Violation]:
    """(f) the private uses across packages that :data:`PRIVATE_ALLOWED` does not excuse."""
    return [v for v in private_uses(root, package) if (v.path, v.message) not in allowed]


def stale_allowances(found, allowed) -> list[str]:
    """Allow-list keys that no longer match anything found (``found``: the keys of what the rule sees)."""
    return sorted(f"{key}: {reason}" for key, reason in allowed.items() if key not in set(found))


def _compiled_functions(mod: Module) -> set[ast.AST]:
    """The function definitions of a module that numba compiles: decorated by one of numba's :data:`COMPILERS`,
    or passed by name to one (``walk_parallel = njit(parallel=True)(_walk)``, ``njit(_f)``)."""
    def compiler(node):
        node = node.func if isinstance(node, ast.Call) else node
        name = _dotted(node, mod.aliases) or ""
        return name.split(".")[0] == "numba" and name.split(".")[-1] in COMPILERS
    wrapped = set()
    for node in ast.walk(mod.tree):
        if isinstance(node, ast.Call) and (compiler(node.func) or (isinstance(node.func, ast.Call)
                                                                   and compiler(node.func.func))):
            wrapped |= {a.id for a in node.args if isinstance(a, ast.Name)}
    return {node for node in ast.walk(mod.tree) if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
            and (node.name in wrapped or any(compiler(d) for d in node.decorator_list))}


def _functions(tree: ast.Module):
    """``(qualname, node, is_method)`` of every function definition, nested ones and methods included."""
    def visit(body, prefix, in_class):
        for node in body:
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                yield prefix + node.name, node, in_class
                yield from visit(node.body, f"{prefix}{node.name}.", False)
            elif isinstance(node, ast.ClassDef):
                yield from visit(node.body, f"{prefix}{node.name}.", True)
            elif isinstance(node, (ast.If, ast.Try, ast.With, ast.For, ast.While)):
                yield from visit([n for f in ("body", "orelse", "finalbody", "handlers") for n in getattr(node, f, [])
                                  if isinstance(n, ast.stmt) or isinstance(n, ast.excepthandler)],
                                 prefix, in_class)
            elif isinstance(node, ast.ExceptHandler):
                yield from visit(node.body, prefix, in_class)
    yield from visit(tree.body, "", False)


def n_params(node: ast.FunctionDef, is_method: bool) -> int:
    """Named parameters (positional and keyword-only; not ``*args``, ``**kwargs``, nor a method's ``self``/``cls``,
    a staticmethod's first parameter being its own)."""
    args = node.args
    n = len(args.posonlyargs) + len(args.args) + len(args.kwonlyargs)
    static = any(isinstance(d, ast.Name) and d.id == "staticmethod" for d in node.decorator_list)
    return n - 1 if is_method and not static and (args.posonlyargs or args.args) else n


def long_signatures(root: Path, package: str = PACKAGE, limit: int = MAX_PARAMS) -> list[Violation]:
    """(h) every function, outside numba's compiled loops, with more than ``limit`` parameters; the message is
    ``qualname (n parameters)``."""
    out = []
    for mod in collect_modules(root, package).values():
        compiled = _compiled_functions(mod)
        for qualname, node, is_method in _functions(mod.tree):
            n = n_params(node, is_method)
            if n > limit and node not in compiled:
                out.append(Violation("params", mod.rel, node.lineno, f"{qualname} ({n} parameters)"))
    return out


def _qualname(violation: Violation) -> str:
    return violation.message.split(" (")[0]


def check_long_signatures(root: Path, package: str = PACKAGE, allowed=PARAMS_ALLOWED) -> list[Violation]:
    """(h) the long signatures that :data:`PARAMS_ALLOWED` does not excuse."""
    return [v for v in long_signatures(root, package) if (v.path, _qualname(v)) not in allowed]


def check_computed_imports(root: Path, package: str = PACKAGE, lazy=LAZY_IMPORTS) -> list[Violation]:
    """(g) imports of names computed at run time only in the functions of ``lazy``; each of those resolves to
    modules of the tree (an entry whose function imports nothing, or that names a module not in the tree, is a
    violation too)."""
    mods = collect_modules(root, package)
    out, used = [], set()
    for mod in mods.values():
        for imp in mod.computed_imports:
            if (mod.name, imp.scope) in lazy:
                used.add((mod.name, imp.scope))
            else:
                out.append(Violation("computed-import", mod.rel, imp.line,
                                     f"imports a module named at run time in {imp.scope or '<module>'}"))
    for (name, function), (_why, resolve) in lazy.items():
        targets = resolve(mods) if name in mods else set()
        if (name, function) not in used or not targets <= set(mods):
            out.append(Violation("computed-import", name, 0, f"LAZY_IMPORTS entry {name}.{function} is stale: it "
                                 f"resolves to {sorted(targets)}"))
    return out


def _report(violations) -> str:
    return "\n".join(str(v) for v in violations)


# ------------------------------------------------------------------------------------------------------
# the real tree
# ------------------------------------------------------------------------------------------------------
def test_kernels_import_only_numerics_and_kernels():
    violations = check_kernel_imports(ROOT)
    assert not violations, "\n" + _report(violations)


def test_only_io_touches_files():
    violations = check_file_io(ROOT)
    assert not violations, "\n" + _report(violations)


def test_only_raycast_uses_embree():
    violations = check_embree_confinement(ROOT)
    assert not violations, "\n" + _report(violations)


def test_no_import_cycles():
    cycles = import_cycles(ROOT)
    assert not cycles, "\n" + "\n".join(" <-> ".join(c) for c in cycles)


def test_no_import_cycles_between_stages():
    cycles = stage_cycles(ROOT)
    assert not cycles, "\n" + "\n".join(" <-> ".join(c) for c in cycles)


def test_no_function_level_meshshade_imports():
    violations = check_function_level_imports(ROOT)
    assert not violations, "\n" + _report(violations)


def test_modules_named_at_run_time_only_in_the_lazy_importers():
    violations = check_computed_imports(ROOT)
    assert not violations, "\n" + _report(violations)
    graph = import_graph(ROOT)
    assert {"meshshade.cli.bake", "meshshade.cli.blender"} <= graph["meshshade.cli.main"]  # resolved edges
    assert "meshshade.materials" in graph["meshshade"]


def test_no_private_names_used_across_packages():
    violations = check_private_imports(ROOT)
    assert not violations, ("\nmake the name public (no underscore, documented) or move it:\n"
                            + "\n".join(f"{v.path}:{v.line}: uses {v.message}" for v in violations))


def test_every_private_allowance_is_still_needed():
    """An entry whose use is gone must go too (its owner removes it with the use)."""
    stale = stale_allowances([(v.path, v.message) for v in private_uses(ROOT)], PRIVATE_ALLOWED)
    assert not stale, "\nremove from PRIVATE_ALLOWED:\n" + "\n".join(stale)
    assert all(isinstance(reason, str) and reason.strip() for reason in PRIVATE_ALLOWED.values())


def test_no_function_takes_more_than_twelve_parameters():
    violations = check_long_signatures(ROOT)
    assert not violations, (f"\nmore than {MAX_PARAMS} parameters (group what travels together in a record):\n"
                            + _report(violations))


def test_every_parameter_allowance_is_still_needed():
    stale = stale_allowances([(v.path, _qualname(v)) for v in long_signatures(ROOT)], PARAMS_ALLOWED)
    assert not stale, "\nremove from PARAMS_ALLOWED:\n" + "\n".join(stale)
    assert all(isinstance(reason, str) and reason.strip() for reason in PARAMS_ALLOWED.values())


def test_the_lint_sees_the_whole_package():
    mods = collect_modules(ROOT)
    assert {"meshshade", "meshshade.io", "meshshade.kernels.dipole", "meshshade.raycast"} <= set(mods)
    graph = import_graph(ROOT)
    assert sum(map(len, graph.values())) > len(graph)  # the graph has edges (resolution works)


# ------------------------------------------------------------------------------------------------------
# the checker itself, on a fake package with one planted violation per rule
# ------------------------------------------------------------------------------------------------------
FAKE = {
    "__init__.py": '"""Fake package."""\n',
    "errors.py": "class FakeError(Exception):\n    pass\n",
    "io.py": ("from pathlib import Path\n\n\ndef write(path, text):\n    Path(path).parent.mkdir(exist_ok=True)\n"
              "    with open(path, 'w') as fh:\n        fh.write(text)\n"),
    "kernels/__init__.py": "from meshshade.kernels.good import helper\n",
    "kernels/good.py": ("from __future__ import annotations\n\nimport math\nfrom dataclasses import dataclass\n\n"
                        "import numba\nimport numpy as np\nfrom scipy import special\n\n"
                        "from meshshade.errors import FakeError\nfrom meshshade.kernels import other\n\n\n"
                        "def helper(x):\n    return np.asarray(x) * math.pi + special.k0(1.0) + other.ONE\n"),
    "kernels/other.py": "ONE = 1.0\n",
    "kernels/planted.py": "import os  # PLANTED (a)\n\nSEP = os.sep\n",
    "cli/__init__.py": "",
    "cli/options.py": ("import dataclasses\nimport os\nfrom pathlib import Path\n\n\ndef output_dir(path):\n"
                       "    p = Path(path)\n    p.mkdir(parents=True, exist_ok=True)\n    return p\n\n\n"
                       "def harmless(text, obj):\n    os.path.join(text, 'a')\n"
                       "    return text.replace('a', 'b'), dataclasses.replace(obj, x=1), text.rename(columns={})\n\n\n"
                       "def planted(path):\n    Path(path).write_text('x')  # PLANTED (b)\n"),
    "raycast/__init__.py": "",
    "raycast/backend.py": ("import ctypes\n\nimport embreex\n\n\ndef load():\n"
                           "    return ctypes.CDLL('libembree4.so'), embreex\n"),
    "montecarlo/__init__.py": "",
    "montecarlo/engine.py": "from embreex import rtcore_scene  # PLANTED (c)\n\nfrom meshshade.kernels import helper\n",
    "a.py": "from meshshade import b  # PLANTED (d): a -> b -> a\n",
    "b.py": "import meshshade.a\n",
    "c.py": "def f():\n    import meshshade.errors  # PLANTED (e)\n    return meshshade.errors\n",
}


@pytest.fixture
def fake_root(tmp_path):
    for rel, text in FAKE.items():
        path = tmp_path / "meshshade" / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return tmp_path


def _planted_line(rel):
    return next(i for i, line in enumerate(FAKE[rel].splitlines(), 1) if "PLANTED" in line)


def test_checker_flags_a_non_numeric_kernel_import(fake_root):
    assert [(v.path, v.line) for v in check_kernel_imports(fake_root)] == [
        ("meshshade/kernels/planted.py", _planted_line("kernels/planted.py"))]


def test_checker_flags_file_writes_outside_io(fake_root):
    violations = check_file_io(fake_root, allowed={("meshshade.io", None), ("meshshade.cli.options", "output_dir")})
    assert [(v.path, v.line) for v in violations] == [("meshshade/cli/options.py", _planted_line("cli/options.py"))]
    assert "write_text" in violations[0].message and "planted" in violations[0].message
    # without the allow-list entry the CLI helper is flagged too
    assert len(check_file_io(fake_root, allowed={("meshshade.io", None)})) == 2


def test_checker_allows_files_in_every_module_of_the_io_package(tmp_path):
    """A whole-module entry covers a package and every module under it, and nothing else: ``meshshade.io`` allows
    ``meshshade/io/__init__.py`` and ``meshshade/io/ply.py``, not ``meshshade/iota.py`` nor ``meshshade/cli/io.py``."""
    files = {"__init__.py": "", "io/__init__.py": "from meshshade.io.ply import write\n",
             "io/ply.py": "def write(path):\n    open(path, 'w').close()\n",
             "io/jobs/__init__.py": "import shutil\n\n\ndef remove(path):\n    shutil.rmtree(path)\n",
             "iota.py": "def write(path):\n    open(path, 'w').close()  # PLANTED\n",
             "cli/__init__.py": "", "cli/io.py": "import os\n\n\ndef drop(path):\n    os.unlink(path)  # PLANTED\n"}
    for rel, text in files.items():
        (tmp_path / "meshshade" / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / "meshshade" / rel).write_text(text)
    violations = check_file_io(tmp_path, allowed={("meshshade.io", None)})
    assert sorted((v.path, v.line) for v in violations) == [("meshshade/cli/io.py", 5), ("meshshade/iota.py", 2)]
    assert len(check_file_io(tmp_path, allowed=set())) == 4  # the io package's own writes are seen


@pytest.mark.parametrize("snippet", [
    "open('f', 'w')", "os.makedirs('d')", "os.replace('a', 'b')", "shutil.copy('a', 'b')",
    "tempfile.mkdtemp()", "np.save('f', x)", "np.savetxt('f', x)", "fig.savefig('f.png')",
    "Path('f').unlink()", "Path('f').touch()", "Path('f').write_bytes(b'')", "Path('a').rename('b')",
    "Path('a').replace('b')", "oiio.ImageOutput.create('f.exr')", "oiio.ImageBuf(spec).write('f.exr')",
    "remove('f')"])
def test_checker_knows_every_way_to_touch_a_file(tmp_path, snippet):
    pkg = tmp_path / "meshshade"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "stage.py").write_text("import os\nimport shutil\nimport tempfile\nfrom os import remove\n"
                                  "from pathlib import Path\n\nimport numpy as np\nimport OpenImageIO as oiio\n\n\n"
                                  f"def f(x, fig, spec):\n    {snippet}\n")
    assert len(check_file_io(tmp_path)) == 1, snippet


def test_checker_flags_embreex_outside_raycast(fake_root):
    assert [(v.path, v.line) for v in check_embree_confinement(fake_root)] == [
        ("meshshade/montecarlo/engine.py", _planted_line("montecarlo/engine.py"))]
    (fake_root / "meshshade" / "light.py").write_text(
        "import ctypes\n\nLIB = ctypes.cdll.LoadLibrary('libembree4.so')\n")
    assert [v.path for v in check_embree_confinement(fake_root)] == ["meshshade/light.py",
                                                                    "meshshade/montecarlo/engine.py"]


def test_checker_finds_the_planted_cycle(fake_root):
    assert import_cycles(fake_root) == [["meshshade.a", "meshshade.b"]]
    graph = import_graph(fake_root)
    # "from meshshade import b" resolves to the submodule; "from meshshade.kernels import helper" to the package
    assert graph["meshshade.a"] == {"meshshade.b"}
    assert graph["meshshade.montecarlo.engine"] == {"meshshade.kernels"}
    assert graph["meshshade.kernels.good"] == {"meshshade.errors", "meshshade.kernels.other"}
    assert graph["meshshade.c"] == {"meshshade.errors"}  # function-level imports are edges too


def test_checker_finds_a_cycle_between_stages(tmp_path):
    files = {"__init__.py": "", "light/__init__.py": "", "transport/__init__.py": "",
             "light/samples.py": "from meshshade.transport import bake  # light -> transport\n",
             "transport/bake.py": "from meshshade.light import spec  # transport -> light\n",
             "light/spec.py": "X = 1\n"}
    for rel, text in files.items():
        (tmp_path / "meshshade" / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / "meshshade" / rel).write_text(text)
    assert import_cycles(tmp_path) == []  # no module-level cycle...
    assert stage_cycles(tmp_path) == [["meshshade.light", "meshshade.transport"]]  # ...but the stages loop


def test_checker_finds_cycles_through_function_level_imports(fake_root):
    (fake_root / "meshshade" / "b.py").write_text("def f():\n    from meshshade import c\n")
    (fake_root / "meshshade" / "a.py").write_text("")
    (fake_root / "meshshade" / "errors.py").write_text("def g():\n    import meshshade.c\n")
    assert import_cycles(fake_root) == [["meshshade.c", "meshshade.errors"]]


def test_checker_flags_private_names_used_across_packages(tmp_path):
    """Private names and modules are free within their directory and flagged from any other, however reached."""
    files = {
        "__init__.py": "from meshshade.io import _reading  # PLANTED: the root package is another directory\n",
        "io/__init__.py": "from meshshade.io._reading import _decode\n",
        "io/_reading.py": "def _decode(b):\n    return b\n\n\ndef decode(b):\n    return b\n",
        "io/meshes.py": ("from meshshade.io import _reading\nfrom meshshade.io._reading import _decode\n"
                         "from . import _reading as R\n\nX = _reading._decode, R._decode, _decode\n"),
        "io/formats/__init__.py": "",
        "io/formats/ply.py": "from .._reading import decode  # PLANTED: a subpackage is another directory\n",
        "kernels/__init__.py": "__version__ = '1'\n",
        "kernels/policies.py": ("_INV_SAT = 0.5\n\n\nclass Policy:\n    def _step(self):\n"
                                "        return _INV_SAT\n"),
        "transport/__init__.py": "",
        "transport/x.py": ("from __future__ import annotations\n\n"
                           "import meshshade.kernels.policies\n"
                           "from meshshade.kernels import __version__, policies as P\n"
                           "from meshshade.kernels.policies import Policy, _INV_SAT  # PLANTED\n\n"
                           "A = P._INV_SAT  # PLANTED\n"
                           "B = meshshade.kernels.policies._INV_SAT  # PLANTED\n"
                           "C = Policy._step  # PLANTED\n"
                           "D = Policy()._step, __version__, P.Policy\n"),
        "transport/y.py": "from meshshade.io._reading import decode  # PLANTED: a private module\n",
        "transport/z.py": "import meshshade.io._reading as R  # PLANTED\n",
    }
    for rel, text in files.items():
        (tmp_path / "meshshade" / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / "meshshade" / rel).write_text(text)
    found = sorted((v.path, v.line, v.message) for v in private_uses(tmp_path))
    planted = sorted((f"meshshade/{rel}", i) for rel, text in files.items()
                     for i, line in enumerate(text.splitlines(), 1) if "PLANTED" in line)
    assert sorted({(path, line) for path, line, _ in found}) == planted
    assert ("meshshade/transport/x.py", 5, "meshshade.kernels.policies._INV_SAT") in found
    assert ("meshshade/transport/x.py", 9, "meshshade.kernels.policies.Policy._step") in found
    assert ("meshshade/transport/z.py", 1, "meshshade.io._reading") in found
    assert ("meshshade/io/formats/ply.py", 1, "meshshade.io._reading") in found
    # an allow-list entry excuses exactly its (module, name); unused entries are reported
    allowed = {(path, name): "a reason" for path, _, name in found if path == "meshshade/transport/x.py"}
    assert {v.path for v in check_private_imports(tmp_path, allowed=allowed)} == {
        "meshshade/__init__.py", "meshshade/io/formats/ply.py", "meshshade/transport/y.py",
        "meshshade/transport/z.py"}
    stale = {**allowed, ("meshshade/transport/x.py", "meshshade.kernels.policies._GONE"): "gone"}
    assert stale_allowances([(p, n) for p, _, n in found], stale) == [
        "('meshshade/transport/x.py', 'meshshade.kernels.policies._GONE'): gone"]


def test_checker_flags_long_signatures_outside_compiled_loops(tmp_path):
    """13 parameters are flagged wherever they are (positional or keyword-only, a method's ``self`` aside), except
    in numba's compiled loops, however they are compiled."""
    p12, p13 = ", ".join(f"a{i}" for i in range(12)), ", ".join(f"a{i}" for i in range(13))
    kw13 = ", ".join(f"a{i}" for i in range(5)) + ", *, " + ", ".join(f"b{i}" for i in range(8))
    text = (f"import numba\nfrom numba import njit, prange\nfrom somewhere import jit\n\n\n"
            f"def long({p13}):  # PLANTED\n    pass\n\n\n"
            f"def options({kw13}):  # PLANTED\n    pass\n\n\n"
            f"def twelve({p12}, *args, **kwargs):\n    pass\n\n\n"
            f"class Walk:\n    def __init__(self, {p12}):\n        pass\n\n"
            f"    @staticmethod\n    def step({p13}):  # PLANTED\n        pass\n\n"
            f"    @classmethod\n    def build(cls, {p12}):\n        pass\n\n\n"
            f"def outer():\n    def inner({p13}):  # PLANTED\n        pass\n    return inner\n\n\n"
            f"@njit(cache=True)\ndef loop({p13}):\n    pass\n\n\n"
            f"@numba.njit\ndef loop2({p13}):\n    pass\n\n\n"
            f"@numba.vectorize\ndef ufunc({p13}):\n    pass\n\n\n"
            f"def _walk({p13}):\n    pass\n\n\n"
            f"walk_parallel = njit(parallel=True, nogil=True)(_walk)\n\n\n"
            f"@jit\ndef not_numba({p13}):  # PLANTED: another library's jit\n    pass\n")
    (tmp_path / "meshshade").mkdir()
    (tmp_path / "meshshade" / "__init__.py").write_text("")
    (tmp_path / "meshshade" / "walks.py").write_text(text)
    found = long_signatures(tmp_path)
    assert [v.line for v in found] == [i for i, line in enumerate(text.splitlines(), 1) if "PLANTED" in line]
    assert [v.message for v in found] == ["long (13 parameters)", "options (13 parameters)",
                                          "Walk.step (13 parameters)", "outer.inner (13 parameters)",
                                          "not_numba (13 parameters)"]
    allowed = {("meshshade/walks.py", "options"): "a public entry point", ("meshshade/walks.py", "gone"): "gone"}
    assert [_qualname(v) for v in check_long_signatures(tmp_path, allowed=allowed)] == [
        "long", "Walk.step", "outer.inner", "not_numba"]
    stale = stale_allowances([(v.path, _qualname(v)) for v in found], allowed)
    assert stale == ["('meshshade/walks.py', 'gone'): gone"]
    assert long_signatures(tmp_path, limit=13) == []


def test_checker_flags_function_level_meshshade_imports(fake_root):
    assert [(v.path, v.line) for v in check_function_level_imports(fake_root)] == [
        ("meshshade/c.py", _planted_line("c.py"))]


def test_checker_confines_computed_imports_to_the_lazy_importers(fake_root):
    """A computed-name import is allowed only in a LAZY_IMPORTS function, whose targets are graph edges (a cycle
    through one is found) and whose literal function-level imports rule (e) accepts."""
    pkg = fake_root / "meshshade"
    (pkg / "lazy.py").write_text("import importlib\n\nTABLE = {'x': 'meshshade.a'}\n\n\n"
                                 "def load(name):\n    importlib.import_module('meshshade.errors')\n"
                                 "    return importlib.import_module(TABLE[name])\n\n\n"
                                 "def other(name):\n    return importlib.import_module(name)  # PLANTED (g)\n")
    (pkg / "a.py").write_text("import meshshade.lazy\n")
    lazy = {("meshshade.lazy", "load"): ("test", _table_values("meshshade.lazy", "TABLE"))}
    assert [(v.path, v.line) for v in check_computed_imports(fake_root, lazy=lazy)] == [("meshshade/lazy.py", 12)]
    assert "meshshade/lazy.py" not in {v.path for v in check_function_level_imports(fake_root, lazy=lazy)}
    assert ["meshshade.a", "meshshade.lazy"] in import_cycles_with(fake_root, lazy)
    stale = {**lazy, ("meshshade.lazy", "gone"): ("test", lambda mods: {"meshshade.a"})}
    assert [v.message for v in check_computed_imports(fake_root, lazy=stale) if v.line == 0] == [
        "LAZY_IMPORTS entry meshshade.lazy.gone is stale: it resolves to ['meshshade.a']"]
    assert len(check_computed_imports(fake_root, lazy={})) == 2  # without the entry both are flagged


def import_cycles_with(root, lazy):
    return sorted(c for c in strongly_connected_components(import_graph(root, lazy=lazy)) if len(c) > 1)


def test_relative_imports_are_resolved(tmp_path):
    pkg = tmp_path / "meshshade" / "kernels"
    pkg.mkdir(parents=True)
    (tmp_path / "meshshade" / "__init__.py").write_text("")
    (tmp_path / "meshshade" / "io.py").write_text("")
    (pkg / "__init__.py").write_text("from . import x\n")
    (pkg / "x.py").write_text("from ..io import load\nfrom .y import z\n")
    (pkg / "y.py").write_text("z = 1\n")
    graph = import_graph(tmp_path)
    assert graph["meshshade.kernels"] == {"meshshade.kernels.x"}
    assert graph["meshshade.kernels.x"] == {"meshshade.io", "meshshade.kernels.y"}
    assert [v.message for v in check_kernel_imports(tmp_path)] == ["kernel module imports meshshade.io"]


def test_scc_on_a_known_graph():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a", "d"}, "d": {"e"}, "e": {"d"}, "f": set()}
    comps = strongly_connected_components(graph)
    assert sorted(comps) == [["a", "b", "c"], ["d", "e"], ["f"]]
    deep = {str(i): {str(i + 1)} for i in range(sys.getrecursionlimit() + 10)}
    deep[str(len(deep))] = {"0"}
    assert len(strongly_connected_components(deep)) == 1  # iterative: no recursion limit


def shadowed_submodules(root: Path, package: str = PACKAGE) -> list[str]:
    """Names a package's ``__init__`` binds that are also the names of its own submodules: after the import,
    ``pkg.name`` is the object, not the module, so ``import pkg.name as m`` and mkdocstrings resolve the wrong one."""
    out = []
    for init in sorted((root / package).rglob("__init__.py")):
        pkg_dir = init.parent
        subs = {p.stem for p in pkg_dir.glob("*.py") if p.stem != "__init__"}
        subs |= {p.name for p in pkg_dir.iterdir() if (p / "__init__.py").is_file()}
        for node in ast.walk(ast.parse(init.read_text())):
            if isinstance(node, ast.ImportFrom):
                for alias in node.names:
                    bound = alias.asname or alias.name
                    target = f"{node.module}.{alias.name}" if node.module else alias.name
                    own = ".".join(pkg_dir.relative_to(root).parts) + "." + bound
                    if bound in subs and target != own:
                        out.append(f"{init.relative_to(root)}: {bound!r} shadows the submodule {own}")
    return out


def test_no_package_attribute_shadows_a_submodule():
    assert not shadowed_submodules(ROOT), "\n".join(shadowed_submodules(ROOT))


def test_checker_finds_a_shadowed_submodule(tmp_path):
    (tmp_path / "meshshade" / "transport").mkdir(parents=True)
    (tmp_path / "meshshade" / "__init__.py").write_text("")
    (tmp_path / "meshshade" / "transport" / "bake.py").write_text("def bake():\n    pass\n")
    (tmp_path / "meshshade" / "transport" / "__init__.py").write_text("from meshshade.transport.bake import bake\n")
    assert shadowed_submodules(tmp_path) == [
        "meshshade/transport/__init__.py: 'bake' shadows the submodule meshshade.transport.bake"]
