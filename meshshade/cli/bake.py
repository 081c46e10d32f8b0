"""``meshshade bake``: per-vertex radiance of a translucent mesh, written as a coloured PLY, glTF or USD, and/or a
texture of its UV map (thin layer over :func:`meshshade.transport.baking.bake`,
:func:`meshshade.output.texture.bake_texture` and :mod:`meshshade.output.bake_file`).

Its help and arguments are in :mod:`meshshade.cli.arguments.bake`; :mod:`meshshade.cli.main` imports this module
only once they are parsed."""
from __future__ import annotations

import sys

from meshshade.cli.options import (bake_options_from_args, is_painted, lights_from_args, mesh_and_material,
                                   painted_material)
from meshshade.asset_cache import AssetCache
from meshshade.errors import ParameterError
from meshshade.io import check_output_path, read_uv_map
from meshshade.output.bake_file import BAKE_FORMATS, check_bake_output, texture_outputs, write_bake, write_texture
from meshshade.output.texture import bake_texture, check_texture_options
from meshshade.transport import bake, describe_result, mesh_note


def _refine(text):
    if text == "auto":
        return None
    try:
        return int(text)
    except ValueError:
        raise ParameterError(f"--texture-refine must be auto or a whole number, got {text!r}") from None


def run_bake(args) -> int:
    if not args.out and not args.texture:
        raise ParameterError("give --out OUT.ply|.glb|.gltf|.usd (per-vertex) or --texture OUT.exr (a texture), "
                             "or both")
    outs = [args.mesh]
    if args.out:
        check_output_path(args.out, [args.mesh], suffixes=tuple(BAKE_FORMATS))
        check_bake_output(args.out)
        outs.append(args.out)
    if args.npz:
        check_output_path(args.npz, outs, suffixes=(".npz",), option="--npz")
        outs.append(args.npz)
    if args.texture:
        size, padding, refine = check_texture_options(args.texture_size, args.padding, _refine(args.texture_refine))
        for path in texture_outputs(args.texture, atlas=False).values():
            check_output_path(path, outs, suffixes=(path.suffix,), option="--texture")
    options = bake_options_from_args(args, progress=not args.quiet)
    lights = lights_from_args(args)
    mesh, material = mesh_and_material(args, parts_allowed=True)
    if is_painted(args):
        material = painted_material(args, mesh, material)
    texture = None
    if args.texture:
        uv = read_uv_map(args.mesh, mesh)
        if uv is None:   # an automatic atlas, written beside the texture
            check_output_path(texture_outputs(args.texture, atlas=True)["obj"], outs, suffixes=(".obj",),
                              option="--texture (its automatic UV atlas)")
        texture = bake_texture(mesh, material, lights, options, uv=uv, size=size, padding=padding, refine=refine,
                               atlas_cache=AssetCache("uv-atlas"))
        result = texture.vertex_result()
    else:
        result = bake(mesh, material, lights, options)
    written = []
    if texture is not None:
        written += write_texture(texture, mesh, args.texture, lights=lights)
    if args.out:
        write_bake(result, mesh, args.out, npz=args.npz, lights=lights, texture=texture,
                   texture_path=args.texture)
        written += [args.out] + ([args.npz] if args.npz else [])
    if not args.quiet:
        note = mesh_note(result)
        if note:
            print(f"meshshade: note: {note}", file=sys.stderr)
        print(describe_result(result))
        if result.plan is not None:
            print(result.plan.describe())
        if texture is not None:
            print(texture.describe())
        print("wrote " + ", ".join(str(w) for w in written))
    return 0
