#!/usr/bin/env bash
# The Blender add-on's tests with a real Blender (docs/blender.md, "Tests"): a virtual environment with bpy 5.0
# (Blender as a Python module, a ~380 MB wheel, Python 3.11), meshshade installed into it keeping bpy's numpy,
# then pytest on tests/blender (about 1 min after the first install; extra arguments go to pytest).
# The environment is kept in $MESHSHADE_BLENDER_VENV (default .blender-venv) and reused.
set -euo pipefail
cd "$(dirname "$0")/../.."
venv="${MESHSHADE_BLENDER_VENV:-.blender-venv}"
if [ ! -x "$venv/bin/python" ]; then
    python3.11 -m venv "$venv"
    "$venv/bin/python" -m pip install -q --upgrade pip
fi
"$venv/bin/python" -m pip install -q "bpy==5.0.*"
# keep the numpy bpy was built against; pip then picks an OpenImageIO that works with it (3.0.x)
"$venv/bin/python" -c "import numpy; print(f'numpy=={numpy.__version__}')" > "$venv/keep-numpy.txt"
"$venv/bin/python" -m pip install -q -c "$venv/keep-numpy.txt" -e ".[test]"
exec "$venv/bin/python" -m pytest -q -p no:cacheprovider tests/blender tests/light/test_spot.py "$@"
