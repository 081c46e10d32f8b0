"""File input and output: the only package that touches the file system (but for the caches: numba's folders,
which ``meshshade.compiled_cache`` places before numba is imported, and the assets' derived data,
``meshshade.asset_cache``).

Every name of ``__all__`` is importable from ``meshshade.io``; each submodule holds one concept:

* :mod:`meshshade.io.meshes`: reading meshes (OBJ, PLY, OFF, STL, GLB, glTF) in the file's order, converted to mm
  (``load_mesh``, ``read_mesh_arrays``, ``SUPPORTED_MESH_FORMATS``), and a bake's PLY read back
  (``read_baked_ply``, ``BAKED_RADIANCE``);
* :mod:`meshshade.io.part_names`: the names a mesh file gives its faces (an OBJ's usemtl and g, a glTF's
  materials), for materials of parts (``read_face_names``);
* :mod:`meshshade.io.uv_maps`: texture coordinates of a mesh file as per-corner UV maps (``read_uv_map``);
* :mod:`meshshade.io.ply`: the PLY reader and writers (``write_ply``, ``write_mesh_ply``, ``PLY_RESERVED_NAMES``);
* :mod:`meshshade.io.transactions`: atomic outputs (``atomic_write``), outputs that appear together or not at all
  (``output_transaction``, ``detached``), output names and folders checked (``check_output_path``,
  ``output_dir``), ``discard_stdout``;
* :mod:`meshshade.io.writers`: text, JSON, NPZ, figures, bytes, USD and OBJ written; TOML, JSON and JSON lines read;
* :mod:`meshshade.io.images`: EXR and PNG through OpenImageIO (``write_exr``, ``write_png``, ``read_exr``);
* :mod:`meshshade.io.colour_maps`: painted colours read linear (and data maps read raw): a colour map image, an
  OBJ's MTL ``map_Kd``, a PLY's vertex colours, a radius map (``read_colour_map``, ``mtl_colour_map``,
  ``read_vertex_colours``, ``read_data_map``);
* :mod:`meshshade.io.environment_maps`: equirectangular HDR environment maps read and checked
  (``read_environment_map``);
* :mod:`meshshade.io.jobs`: a batch's job folders (``job_folder``, ``remove_stale_parts``), file lists and hashes,
  scratch folders, log files.

What the readers share (text encodings, polygons) is in ``meshshade.io._reading``, the one-line error text in
``meshshade.io._messages``.
"""
from __future__ import annotations

from meshshade.io.colour_maps import mtl_colour_map, read_colour_map, read_data_map, read_vertex_colours
from meshshade.io.environment_maps import read_environment_map
from meshshade.io.images import read_exr, write_exr, write_png
from meshshade.io.jobs import (append_text, file_sha256, folder_files, job_folder, remove_folder, remove_stale_parts,
                               scratch_folder, temp_path)
from meshshade.io.meshes import BAKED_RADIANCE, SUPPORTED_MESH_FORMATS, load_mesh, read_baked_ply, read_mesh_arrays
from meshshade.io.ply import PLY_RESERVED_NAMES, write_mesh_ply, write_ply
from meshshade.io.part_names import read_face_names
from meshshade.io.uv_maps import read_uv_map
from meshshade.io.transactions import (atomic_write, check_output_path, detached, discard_stdout, output_dir,
                                       output_transaction)
from meshshade.io.writers import (read_json, read_json_lines, read_toml, write_bytes, write_figure, write_json,
                                  write_json_lines, write_npz, write_obj, write_text, write_usd)

__all__ = ["SUPPORTED_MESH_FORMATS", "load_mesh", "read_mesh_arrays", "read_baked_ply", "BAKED_RADIANCE",
           "atomic_write", "output_transaction",
           "check_output_path", "output_dir", "discard_stdout",
           "write_ply", "write_mesh_ply", "write_npz", "write_text", "write_json", "write_figure", "PLY_RESERVED_NAMES",
           "write_exr", "write_png", "read_exr", "read_toml", "read_json", "read_json_lines", "write_json_lines",
           "file_sha256", "folder_files", "job_folder", "remove_stale_parts", "detached", "write_bytes", "write_usd",
           "write_obj", "scratch_folder", "remove_folder", "temp_path", "append_text", "read_uv_map",
           "read_environment_map", "read_colour_map", "read_data_map", "mtl_colour_map", "read_vertex_colours",
           "read_face_names"]
