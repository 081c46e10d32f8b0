"""The add-on's bake beside Blender (meshshade.blender.job): ``meshshade bake`` in a child process, its result the
Python API's, its progress read, its cancellation clean. No bpy needed: these run in every environment.

The reference is an independent route to the same numbers: :func:`meshshade.transport.bake` called in this
process on the same mesh and lights, the colour groups summed by the test.
"""
from __future__ import annotations

import math
import time

import numpy as np
import pytest

from meshshade.blender.job import BakeJob, BakeJobError, BakeSettings, light_spec
from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import icosphere
from meshshade.light import BeamLight, DirectionalLight, PointLight, parse_light_spec
from meshshade.light.sources import Spot
from meshshade.materials import Material
from meshshade.transport import BakeOptions, SurfaceOptions, bake


@pytest.mark.parametrize("light", [DirectionalLight((0.1, 0.2, -1.0), 1.234567890123e-3),
                                   PointLight((1 / 3, 2.5, 30.0), 0.7957747154594767),
                                   PointLight((0, 0, 30.0), 2.0, spot=Spot((0.1, 0, -1), 0.6, 0.15)),
                                   BeamLight((0, 0, 30.0), (0, 0, -1), 0.5, 0.25)])
def test_light_specs_read_back_exactly(light):
    assert parse_light_spec(light_spec(light)) == light


def scene():
    V, F = icosphere(8.0, 3)
    V = V + np.array([1.0, -2.0, 0.5])
    groups = [(np.array([1.0, 0.8, 0.6]), [DirectionalLight((0.3, 0.1, -1.0), 1e-3),
                                          PointLight((1.0, -2.0, 40.0), 0.5)]),
              (np.array([0.0, 0.5, 1.0]), [PointLight((30.0, 0.0, 0.0), 2.0,
                                                      spot=Spot((-1.0, 0.0, 0.0), math.radians(40.0), 0.3))])]
    return V, F, groups


def test_job_equals_the_python_api_weighted_by_colour():
    V, F, groups = scene()
    settings = BakeSettings(preset="marble", model="dipole", transport="direct")
    job = BakeJob(V, F, groups, settings)
    seen = []
    radiance = job.wait(on_progress=lambda f, m: seen.append((f, m)), interval=0.02)
    mesh = Mesh.from_arrays(V, F)
    expected = sum(c * bake(mesh, Material.preset("marble"), lights, BakeOptions(
        model="dipole", surface=SurfaceOptions(transport="direct"))).radiance
                   for c, lights in groups)
    np.testing.assert_allclose(radiance, expected, rtol=1e-12, atol=0)
    assert job.fraction == 1.0 and job._dir is None            # the scratch folder is gone
    assert seen and all(0.0 <= f <= 1.0 for f, _ in seen) and seen[0][1].startswith("bake 1/2")
    assert any("mesh:" in line for line in job.summary)


def test_custom_coefficients_are_passed_exactly():
    V, F, groups = scene()
    settings = BakeSettings(preset=None, sigma_s_prime=(1.1, 0.9, 0.7), sigma_a=(0.011, 0.02, 1 / 30), eta=1.41,
                            model="dipole", transport="direct")
    radiance = BakeJob(V, F, groups[:1], settings).wait()
    expected = groups[0][0] * bake(Mesh.from_arrays(V, F), Material((1.1, 0.9, 0.7), (0.011, 0.02, 1 / 30), 1.41),
                                   groups[0][1], BakeOptions(
                                       model="dipole", surface=SurfaceOptions(transport="direct"))).radiance
    np.testing.assert_allclose(radiance, expected, rtol=1e-12)


def test_a_slot_painted_by_an_image_bakes_as_the_api_does(tmp_path):
    """The add-on's "From the object's material" with an Image Texture: the job's CLI bake (--albedo-map over the
    UVs it writes) equals the API's bake of the PaintedMaterial of the same image (rtol 1e-12)."""
    from meshshade.blender.convert import PrincipledSlot, principled_medium
    from meshshade.geometry.procedural import spherical_uv
    from meshshade.io import write_exr
    from meshshade.painted import PaintedMaterial

    V, F = icosphere(8.0, 2)
    uv = spherical_uv(V, F)
    yy, xx = np.mgrid[0:16, 0:32]
    image = np.where(((xx // 4 + yy // 4) % 2 == 0)[..., None], [0.45, 0.3, 0.2], [0.6, 0.5, 0.4])
    path = tmp_path / "paint.exr"
    write_exr(path, image.astype(np.float32))
    medium, _ = principled_medium(PrincipledSlot("Paint", None, str(path), (1.2, 0.6, 0.3), 1.0, 1.3), 1.0)
    settings = BakeSettings(preset=None, sigma_s_prime=medium["sigma_s_prime"], sigma_a=medium["sigma_a"],
                            eta=medium["eta"], albedo_map=medium["albedo_map"])
    sun = DirectionalLight((0.3, 0.1, -1.0), 1e-3)
    radiance = BakeJob(V, F, [(np.ones(3), [sun])], settings, uv=uv).wait()
    base = Material(medium["sigma_s_prime"], medium["sigma_a"], medium["eta"])
    expected = bake(Mesh.from_arrays(V, F), PaintedMaterial(base, image=image.astype(np.float32).astype(np.float64),
                                                            uv=uv), [sun]).radiance
    np.testing.assert_allclose(radiance, expected, rtol=1e-12)
    with pytest.raises(BakeJobError, match="colour map.*needs a UV map"):
        BakeJob(V, F, [(np.ones(3), [sun])], settings)


def test_a_slot_with_a_radius_map_bakes_as_the_api_does(tmp_path):
    """An Image Texture feeding Subsurface Radius (a radius map, eq. (132)): the job's CLI bake (--radius-map over
    the UVs it writes) equals the API's bake of the PaintedMaterial of the same factors (rtol 1e-12)."""
    from meshshade.blender.convert import PrincipledSlot, principled_medium
    from meshshade.geometry.procedural import spherical_uv
    from meshshade.io import write_exr
    from meshshade.kernels.painted_reflectance import albedo_for_reflectance
    from meshshade.painted import PaintedMaterial

    V, F = icosphere(8.0, 2)
    uv = spherical_uv(V, F)
    yy, xx = np.mgrid[0:16, 0:32]
    radius = np.where(((xx // 8) % 2 == 0)[..., None], [1.5, 0.9, 0.6], [0.8, 0.5, 0.3]).astype(np.float32)
    path = tmp_path / "radius.exr"
    write_exr(path, radius)
    colour = (0.5, 0.35, 0.25)
    medium, _ = principled_medium(PrincipledSlot("Skin", colour, None, (1.0, 1.0, 1.0), 1.0, 1.3,
                                                 radius_image=str(path)), 1.0)
    settings = BakeSettings(preset=None, sigma_s_prime=medium["sigma_s_prime"], sigma_a=medium["sigma_a"],
                            eta=medium["eta"], radius_map=medium["radius_map"])
    sun = DirectionalLight((0.3, 0.1, -1.0), 1e-3)
    radiance = BakeJob(V, F, [(np.ones(3), [sun])], settings, uv=uv).wait()
    base = Material(medium["sigma_s_prime"], medium["sigma_a"], medium["eta"])
    np.testing.assert_allclose(base.albedo_prime, albedo_for_reflectance(np.array(colour), 1.3), rtol=1e-12)
    expected = bake(Mesh.from_arrays(V, F), PaintedMaterial(base, radius_image=radius.astype(np.float64), uv=uv),
                    [sun]).radiance
    np.testing.assert_allclose(radiance, expected, rtol=1e-12)
    with pytest.raises(BakeJobError, match="radius map.*needs a UV map"):
        BakeJob(V, F, [(np.ones(3), [sun])], settings)


def test_parts_of_different_media_bake_as_the_api_parts():
    """Faces of several media (the add-on's material slots): the job writes them as usemtl parts and passes each
    part's coefficients; the result equals the API's PartedMaterial bake (rtol 1e-12)."""
    from meshshade.parts import PartedMaterial

    V, F = icosphere(8.0, 3)
    centre = V[F].mean(axis=1)
    face_part = np.where(centre[:, 0] < -2.0, 0, np.where(centre[:, 2] > 4.0, 1, -1))
    rest = Material((1.1, 0.9, 0.7), (0.011, 0.02, 1 / 30), 1.3)
    a = Material((2.19, 2.62, 3.0), (0.0021, 0.0041, 0.0071), 1.3)
    b = Material((0.5, 0.6, 0.7), (0.2, 0.1, 0.05), 1.3)
    settings = BakeSettings(preset=None, sigma_s_prime=(1.1, 0.9, 0.7), sigma_a=(0.011, 0.02, 1 / 30), eta=1.3,
                            parts=(("slot1", (2.19, 2.62, 3.0), (0.0021, 0.0041, 0.0071)),
                                   ("slot2", (0.5, 0.6, 0.7), (0.2, 0.1, 0.05))))
    sun = DirectionalLight((0.3, 0.1, -1.0), 1e-3)
    radiance = BakeJob(V, F, [(np.ones(3), [sun])], settings, face_part=face_part).wait()
    mesh = Mesh.from_arrays(V, F)
    # the parts named first, in order, the rest last (as PartedMaterial.from_names orders them)
    expected = bake(mesh, PartedMaterial([a, b, rest], np.where(face_part < 0, 2, face_part),
                                         ["slot1", "slot2", "rest"]), [sun]).radiance
    np.testing.assert_allclose(radiance, expected, rtol=1e-12, atol=1e-15 * expected.max())
    with pytest.raises(BakeJobError, match="each face's part"):
        BakeJob(V, F, [(np.ones(3), [sun])], settings)


def test_a_mistake_is_the_commands_one_line_error(tmp_path):
    V, F, groups = scene()
    job = BakeJob(V, F, groups, BakeSettings(preset="no-such-medium"), log=tmp_path / "log.txt")
    with pytest.raises(BakeJobError) as info:
        job.wait()
    text = str(info.value)
    assert "\n" not in text and "no-such-medium" in text and "exit 2" in text and "Traceback" not in text
    assert job._dir is None
    assert "no-such-medium" in (tmp_path / "log.txt").read_text()


def test_a_missing_python_is_refused():
    V, F, groups = scene()
    with pytest.raises(BakeJobError, match="does not exist"):
        BakeJob(V, F, groups, BakeSettings(), python="/no/such/python").start()


def test_cancel_stops_the_child_at_once_and_leaves_nothing():
    V, F = icosphere(20.0, 6)   # 41k vertices, exact geodesics: long enough to be cancelled mid-way
    job = BakeJob(V, F, [(np.ones(3), [DirectionalLight((0, 0, -1), 1e-3)])],
                  BakeSettings(preset="skin1", model="curved", transport="direct")).start()
    folder, proc = job._dir, job._runs[0].proc
    assert folder.is_dir()
    time.sleep(1.0)
    assert not job.poll()
    t0 = time.monotonic()
    job.cancel()
    assert time.monotonic() - t0 < 5.0
    assert proc.poll() is not None and not folder.exists()
    with pytest.raises(BakeJobError, match="cancelled"):
        job.poll()
