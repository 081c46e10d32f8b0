"""``meshshade demo``: the README's images, written into one folder.

1. **The paper's Figure 1, corrected** (``figure1_potato.*``, ``figure1_marble.*``, ``figure1.png``): a sphere of
   radius 10 mm lit by a unit pencil beam at normal incidence, entering at the image centre, seen orthographically
   along the beam. Left half: the exact sphere series; right half: Jensen's dipole at the chord distance. The image
   is built analytically per sample (no mesh): pixel (x, y) -> surface point -> angle theta = asin(r/R0) from the
   entry point -> M = F_t(0) R(theta) -> L = F_t(cos theta) M / (pi C) (render.py's exit convention). This is
   exact (no tessellation, no interpolation) and takes well under a second. Drago 2003 tone mapping over both
   halves together, so the halves share one exposure.
2. **Profiles** (``profiles.png``): sigma_s' = 1, sigma_a = 0.01 /mm, eta 1.3, spheres of 2, 5, 10 and 50 mm;
   dipole vs exact vs curved.
3. **A real-looking mesh** (``pebble/``): the procedural pebble of ``assets/`` (at subdivision 4, 2,562 vertices,
   so the demo stays under a minute; ``assets/pebble.ply`` is the same shape at level 5) in marble under a
   directional light, the default model (diffusion inside the pebble's volume with the analytic near field,
   docs/physics.md §15) vs the planar dipole, with every ``compare`` output. The dipole's bake uses the ``arc``
   geodesics (curvature-corrected chords, 1e-4 on smooth meshes like this one) and the direct sum
   (``transport="direct"``): under this light ``transport="auto"`` builds the hierarchical far field, finds it not
   accurate enough for the light and sums directly anyway, the same exitance bit for bit, after compiling the
   hierarchical transport's kernels (32 of the first run's 62 compile CPU seconds; issue 48).
"""
from __future__ import annotations

import multiprocessing
import os
import time
import warnings
from pathlib import Path

import numpy as np

from meshshade import io, profiles
from meshshade.geometry import procedural
from meshshade.geometry.mesh import Mesh
from meshshade.kernels.dipole import dipole_profile
from meshshade.kernels.fresnel import fresnel_transmittance_entry
from meshshade.kernels.sphere import sphere_series_profile
from meshshade.light import DirectionalLight
from meshshade.materials import Material
from meshshade.output import compare, render, report
from meshshade.names import DEFAULT_MODEL
from meshshade.surface.options import SurfaceOptions
from meshshade.transport.baking import bake
from meshshade.transport.options import BakeOptions


def figure1_radiance(material: Material, *, R0_mm=10.0, width=384, spp=4, seed=0, half_width_mm=None):
    """Analytic orthographic images (exact sphere, chord dipole) of a sphere lit by a unit normal beam.

    Returns (exact_rgb, dipole_rgb, alpha): (H, W, 3) W/(mm^2 sr) premultiplied radiance, (H, W) coverage.
    """
    hw = half_width_mm or 1.1 * R0_mm
    off = render.sample_offsets(spp, np.random.default_rng(seed))
    jj, ii = np.meshgrid(np.arange(width), np.arange(width), indexing="xy")
    theta_grid = np.linspace(0.0, np.pi / 2, 4097)
    ft0 = float(fresnel_transmittance_entry(1.0, material.eta))
    tables = []
    for c in range(3):
        ch = material.channel(c)
        st, par = ch["sigma_t_prime"], {"albedo_prime": ch["albedo_prime"], "eta": ch["eta"]}
        exact = sphere_series_profile(theta_grid, R0_opt=R0_mm * st, **par) * st * st
        chord = 2 * R0_mm * np.sin(theta_grid / 2)
        dip = dipole_profile(chord * st, **par) * st * st
        tables.append((np.log(np.maximum(exact, 1e-300)), np.log(np.maximum(dip, 1e-300))))
    out = [np.zeros((width, width, 3)), np.zeros((width, width, 3))]
    alpha = np.zeros((width, width))
    for ox, oy in off:
        x = (2 * (jj + ox) / width - 1) * hw
        y = (1 - 2 * (ii + oy) / width) * hw
        r = np.hypot(x, y)
        inside = r < R0_mm
        th = np.arcsin(np.clip(r[inside] / R0_mm, 0, 1))
        for k in range(2):
            M = np.stack([ft0 * np.exp(np.interp(th, theta_grid, tables[c][k])) for c in range(3)], axis=-1)
            out[k][inside] += render.exit_radiance(M, np.cos(th), material.eta)
        alpha[inside] += 1
    return out[0] / spp, out[1] / spp, alpha / spp


def _figure1_part(out: Path, small: bool) -> dict:
    """(1) Figure 1, corrected: {name: path}."""
    files = {}
    w = 96 if small else 384
    panels = []
    for name in ("potato", "marble"):
        mat = Material.preset(name)
        ex, dp, a = figure1_radiance(mat, width=w, spp=2 if small else 4)
        rgb = compare.split_image(ex, dp)
        meta = {"model": "left exact sphere series, right planar dipole (chord)", "material": mat.describe(),
                "lights": "beam 1 W at normal incidence at the image centre", "units": "W/(mm^2 sr) per W",
                "camera": "orthographic along the beam, 22 mm wide"}
        files[f"figure1_{name}.exr"] = io.write_exr(out / f"figure1_{name}.exr", render.image_rgba(rgb, a), meta)
        png = render.display_rgba(rgb, a, operator="drago", background=(0, 0, 0))
        files[f"figure1_{name}.png"] = io.write_png(out / f"figure1_{name}.png", png)
        panels.append(png)
    gap = np.zeros((w, max(2, w // 32), 4), np.uint8)
    gap[..., 3] = 255
    files["figure1.png"] = io.write_png(out / "figure1.png", np.concatenate([panels[0], gap, panels[1]], axis=1))
    return files


def _profiles_part(out: Path, small: bool) -> dict:
    """(2) profiles: {name: path}."""
    mat = Material(1.0, 0.01, eta=1.3)
    shapes = [profiles.Shape.make("sphere", r) for r in (2.0, 5.0, 10.0, 50.0)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # distances beyond half the small spheres' girth are dropped, as intended
        rows = profiles.profile_rows(mat, np.linspace(0.0, 20.0, 21 if small else 81),
                                     models=["dipole", "exact", "curved"], shapes=shapes)
    return {"profiles.png": io.write_figure(out / "profiles.png", report.profile_figure(rows, material=mat,
                                                                                        shapes=shapes))}


#: the pebble comparison's lights, material and the dipole side's options (one place: its warm-up uses them too)
PEBBLE_LIGHT = (-1.0, -0.3, -0.35)   # from the right, grazing: light bleeds past the terminator
PEBBLE_SURFACE = SurfaceOptions(geodesic="arc", transport="direct")


def _warm_dipole_side() -> None:
    """Bake the pebble's dipole side on the pebble at subdivision 1 (42 vertices) and drop it: numba compiles and
    caches the dipole side's kernels in this process while the pebble's volume bake runs in the other, which then
    reads them from the cache instead of compiling them after its volume bake (on the first run: about 9 of the
    second process's seconds; later runs: a few milliseconds here)."""
    V, F = procedural.pebble(subdivisions=1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")   # its coarse curvature fit warns; nothing of it is shown
        bake(Mesh.from_arrays(V, F, source="procedural.pebble"), Material.preset("marble"),
             [DirectionalLight(PEBBLE_LIGHT)], BakeOptions(model="dipole", surface=PEBBLE_SURFACE))


def _pebble_part(out: Path, small: bool):
    """(3) a real-looking mesh, the default model (diffusion in its volume) vs the planar dipole: ({name: path},
    the comparison's statistics)."""
    V, F = procedural.pebble(subdivisions=3 if small else 4)
    mesh = Mesh.from_arrays(V, F, source="procedural.pebble")
    mat = Material.preset("marble")
    lights = [DirectionalLight(PEBBLE_LIGHT)]
    models = (DEFAULT_MODEL, "dipole")
    cam = render.auto_camera(mesh, (0.0, 0.0, -1.0))
    size = 96 if small else 384
    cmp = compare.run_comparison(mesh, mat, lights, models,
                                 compare.CompareOptions(width=size, height=size, spp=2 if small else 4),
                                 surface=PEBBLE_SURFACE, camera=cam)
    io.output_dir(out / "pebble")
    meta = {"material": mat.describe(), "lights": "directional -1,-0.3,-0.35 (1 W/mm^2)",
            "units": "W/(mm^2 sr) per W/mm^2", "model": f"left {DEFAULT_MODEL}, right dipole"}
    files = {f"pebble/{Path(p).name}": p
             for p in compare.save_comparison(cmp, out / "pebble", models=models, metadata=meta, background=(0, 0, 0))}
    st = cmp["stats"]
    return files, {"max_rel_diff": float(st["max_rel_diff"]), "p95_rel_diff": float(st["p95_rel_diff"])}


def run_demo(out_dir="meshshade-demo", *, small=False, log=print) -> dict:
    """Write the three demo parts into ``out_dir``; returns {name: path} and prints where each file is.

    With more than one core the pebble (3) runs in a second process while this one makes (1) and (2) and compiles
    the pebble's dipole side (:func:`_warm_dipole_side`): on the first run most of the demo's time is numba
    compiling, which one process does on one thread, so the compilations overlap (the outputs are the same either
    way)."""
    t_start = time.perf_counter()
    out = io.output_dir(out_dir)
    files = {}
    if (os.cpu_count() or 1) > 1:
        pool = multiprocessing.get_context("spawn").Pool(1)
        try:
            pebble = pool.apply_async(_pebble_part, (out, small))
            files.update(_figure1_part(out, small))
            files.update(_profiles_part(out, small))
            _warm_dipole_side()
            pebble_files, st = pebble.get()
        except BaseException:   # an error or a signal here: the other process stops before anything is cleaned up
            pool.terminate()
            pool.join()
            raise
        pool.close()
        pool.join()
    else:
        files.update(_figure1_part(out, small))
        files.update(_profiles_part(out, small))
        pebble_files, st = _pebble_part(out, small)
    files.update(pebble_files)
    elapsed = time.perf_counter() - t_start
    for k, p in files.items():
        log(f"wrote {p}")
    log(f"pebble: {DEFAULT_MODEL} vs dipole, max |rel diff| {st['max_rel_diff']:.3g}, p95 {st['p95_rel_diff']:.3g} "
        f"over vertices; demo took {elapsed:.1f} s")
    return files
