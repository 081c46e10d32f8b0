"""Generate docs/api/*.md (one page per pipeline package, one mkdocstrings block per public module).

    python tools/docs/gen_api_docs.py            # rewrite docs/api/ from the package tree
    python tools/docs/gen_api_docs.py --check    # exit 1 if docs/api/ is out of date (tests/test_docs.py runs this)

A module added to the package appears in the API reference only once this has been run; the check keeps the
committed pages in step with the tree.
"""
import ast
import pathlib
import sys

ROOT = pathlib.Path(__file__).resolve().parents[2]
OUT = ROOT / "docs" / "api"
CHECK = "--check" in sys.argv[1:]

# page -> (package, preferred order of modules / subpackages; the rest follow alphabetically)
PAGES = {
    "meshshade": ("meshshade", ["errors", "units", "materials", "medium", "compiled_cache", "memo", "check",
                                "profiles", "preview", "demo"]),
    "io": ("meshshade.io", ["meshes", "ply", "transactions", "writers", "images", "jobs"]),
    "kernels": ("meshshade.kernels", ["optics", "fresnel", "dipole", "single_scattering", "beam_diffusion", "sphere",
                                      "cylinder", "curvature", "auxiliary", "coefficients", "table", "policies",
                                      "profile"]),
    "geometry": ("meshshade.geometry", ["mesh", "topology", "procedural", "curvature", "convexity", "geodesics",
                                        "exact", "neighbourhoods", "arc"]),
    "raycast": ("meshshade.raycast", ["scene", "backends", "embree", "numpy_twin", "embree_direct"]),
    "light": ("meshshade.light", ["sources", "spec", "samples", "shadows"]),
    "transport": ("meshshade.transport", ["baking", "options", "result"]),
    "surface": ("meshshade.surface", ["baking", "options", "models", "pair_kernel", "kernel_evaluation", "patch_average", "source_factors",
                                      "gather", "zones", "auto", "sample_groups", "farfield", "farfield_loops",
                                      "direct_sum", "hierarchical", "hierarchy_loops"]),
    "output": ("meshshade.output", ["bake_file", "render", "tonemap", "compare", "report"]),
    "montecarlo": ("meshshade.montecarlo", ["simulation", "boundary", "engine", "emitter", "emission", "sampling",
                                            "fused_walk", "loops", "shapes", "interior", "tallies",
                                            "wavefront_oracle"]),
    "volume": ("meshshade.volume", ["transport", "options", "resolution", "surface", "inside", "lattice", "cutfem",
                                    "multigrid", "long_range", "remainder"]),
    "bench": ("meshshade.bench", ["scenes", "plan", "runner", "references", "report"]),
    "batch": ("meshshade.batch", ["runner", "jobs", "dask_cluster"]),
    "blender": ("meshshade.blender", ["convert", "job", "addon"]),
    "cli": ("meshshade.cli", ["main", "options", "demo", "profile", "check", "bake", "render", "compare", "mc",
                              "bench", "batch", "jobs", "blender"]),
}
SUBPAGES = {"meshshade": False}  # the top-level page lists only top-level modules (subpackages have pages)


def path_of(dotted):
    p = ROOT / dotted.replace(".", "/")
    return p / "__init__.py" if p.is_dir() else p.with_suffix(".py")


def children(pkg, pref):
    d = ROOT / pkg.replace(".", "/")
    names = [p.stem for p in d.glob("*.py") if not p.stem.startswith("_")]
    names += [p.name for p in d.iterdir() if p.is_dir() and (p / "__init__.py").exists() and not p.name.startswith("_")]
    names = sorted(set(names))
    return [n for n in pref if n in names] + [n for n in names if n not in pref]


def summary(dotted):
    try:
        doc = ast.get_docstring(ast.parse(path_of(dotted).read_text()))
    except SyntaxError:
        doc = None
    return (doc or "").strip().split("\n\n")[0].replace("\n", " ").replace("|", "\\|")


def walk(pkg, pref, recurse):
    """Yield dotted names of modules and subpackages below pkg, depth first, in preferred order."""
    for n in children(pkg, pref):
        dotted = f"{pkg}.{n}"
        is_pkg = (ROOT / dotted.replace(".", "/")).is_dir()
        if is_pkg and not recurse:
            continue
        yield dotted, is_pkg
        if is_pkg:
            yield from walk(dotted, pref, recurse)


stale = []
if not CHECK:
    OUT.mkdir(parents=True, exist_ok=True)
for page, (top, pref) in PAGES.items():
    recurse = SUBPAGES.get(page, True)
    lines = [f"# {top}", "", f"::: {top}", "    options:", "      members: false", "      show_root_heading: false", ""]
    if page == "meshshade":
        lines += ["Top-level modules; each pipeline stage has its own page (see the [API reference](index.md)).", ""]
    rows, blocks = [], []
    for dotted, is_pkg in walk(top, pref, recurse):
        rows.append(f"| [`{dotted}`][{dotted}] | {summary(dotted)} |")
        if is_pkg:
            blocks += [f"::: {dotted}", "    options:", "      members: false", ""]
        else:
            blocks += [f"::: {dotted}", ""]
    lines += ["| module | what it holds |", "|---|---|"] + rows + [""] + blocks
    text = "\n".join(lines).rstrip() + "\n"
    target = OUT / f"{page}.md"
    if CHECK:
        if not target.exists() or target.read_text() != text:
            stale.append(str(target.relative_to(ROOT)))
    else:
        target.write_text(text)
        print(page, len(rows))
if stale:
    print("out of date (run python tools/docs/gen_api_docs.py): " + ", ".join(stale))
    sys.exit(1)
