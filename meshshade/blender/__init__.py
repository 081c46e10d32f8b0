"""meshshade in Blender: an add-on that bakes subsurface exitance into a mesh's colour attributes.

Install meshshade into Blender's Python, write the add-on file and enable it (docs/blender.md)::

    "$BLENDER_PYTHON" -m pip install -c keep-numpy.txt meshshade       # keeps Blender's numpy
    "$BLENDER_PYTHON" -m meshshade.cli blender meshshade_addon.py
    # Blender: Edit > Preferences > Add-ons > Install from Disk... > meshshade_addon.py, tick it

or, from Python inside Blender (or with the ``bpy`` module), ``meshshade.blender.register()``. The bake is the
operator ``bpy.ops.object.meshshade_bake`` (its properties are the panel's settings); the panel is in the Object
properties. Modules: :mod:`meshshade.blender.convert` (units and lights, no bpy), :mod:`meshshade.blender.job`
(the bake in a child process, no bpy), :mod:`meshshade.blender.addon` (operator, panel, preferences; needs bpy).
"""
from __future__ import annotations

from meshshade.names import ADDON_MODULE  # the module name of the add-on file addon_source writes

__all__ = ["bl_info", "register", "unregister", "addon_source", "ADDON_MODULE"]

bl_info = {
    "name": "meshshade translucency",
    "author": "meshshade developers",
    "version": (0, 1, 0),
    "blender": (4, 2, 0),
    "location": "Properties > Object > meshshade translucency",
    "description": "Bake curvature-aware subsurface exitance (diffusion theory) into a colour attribute",
    "doc_url": "https://github.com/meshshade/meshshade/blob/main/docs/blender.md",
    "category": "Object",
}


def _needs_blender(*_args, **_kwargs):
    raise ImportError("meshshade.blender.register/unregister run inside Blender (the bpy module is not importable "
                      "here); see docs/blender.md")


try:   # inside Blender (or with the bpy module): the add-on itself; a folder named bpy in the working directory
    from bpy import app  # noqa: F401  (a namespace package without Blender's modules) is not Blender
except ImportError:
    register = unregister = _needs_blender
else:
    from meshshade.blender.addon import register, unregister


def addon_source() -> str:
    """The text of the add-on file Blender's preferences install (a legacy add-on: ``bl_info`` written out, as
    Blender reads it without running the file; the rest imports the installed meshshade)."""
    return (
        '"""meshshade translucency: Blender add-on (written by `meshshade blender`; the code is the meshshade\n'
        'package installed in Blender\'s Python, see docs/blender.md)."""\n'
        f"bl_info = {bl_info!r}\n\n\n"
        "def register():\n"
        "    try:\n"
        "        import meshshade.blender\n"
        "    except ImportError as exc:\n"
        "        raise ImportError(\"meshshade is not installed in Blender's Python (\" + str(exc) + \"); \"\n"
        "                          \"see docs/blender.md\") from None\n"
        "    meshshade.blender.register(__name__)\n\n\n"
        "def unregister():\n"
        "    import meshshade.blender\n"
        "    meshshade.blender.unregister()\n"
    )
