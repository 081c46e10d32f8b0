"""Job files of ``meshshade batch``: jobs (one meshshade command with its options) and sweeps (products of option
values), run by :func:`meshshade.batch.runner.run_batch`.

A job here is exactly one ``meshshade bake | render | compare | mc | profile`` invocation: its options are the
command's long options without the dashes (``cutoff-tol`` or ``cutoff_tol``), ``mesh`` for the input mesh, and
output options (``out``, ``npz``, ``texture``, ``summary``, ``csv``, ``plot``) as plain file names (an ``albedo-map``
or ``radius-map`` file, as the mesh, relative to the job file), which are
written inside the job's own folder (a texture's PNG and atlas beside it). A job therefore produces the same files
as the command run by hand.

Job file (TOML)::

    [defaults]                      # options for every job whose command has them
    units = "mm"
    material = "skin1"

    [[job]]
    name = "spot-sun"               # the job's folder; default: the command and a hash of its options
    command = "bake"
    mesh = "meshes/spot.obj"        # relative to the job file (so is an environment map: "env:maps/studio.exr")
    light = "directional:0,0,-1"    # a repeatable option takes a list: ["beam:...", "point:..."]
    out = "spot.ply"                # default: bake.ply

    [[sweep]]                       # the product of the lists under [sweep.vary]
    command = "bake"
    name = "{mesh}-{material}-{model}"   # optional; default: the command and every varied value
    mesh = "meshes/spot.obj"
    [sweep.vary]
    material = ["skin1", "marble"]
    model = ["dipole", "curved", "auto"]
    light = ["directional:0,0,-1", ["directional:0,0,-1", "point:0,0,80"]]   # one light, then two

:func:`read_jobs` reads such a file, :func:`expand` turns sweeps into jobs (:class:`meshshade.batch.Job` whose
``execute`` is :func:`run_command`); every job is checked by the command's own argument parser before anything runs
(:func:`check_job`), so a typo in an option is one line naming the job and the option, and the batch does not start.
"""
from __future__ import annotations

import argparse
import hashlib
import itertools
import json
import re
import warnings
from pathlib import Path

from meshshade.batch.jobs import NAME_PATTERN, Job, JobFileError
from meshshade.cli import arguments, bake, compare, mc, profile, render
from meshshade.cli.arguments.common import deprecated_aliases
from meshshade.io import output_transaction, read_toml

__all__ = ["COMMANDS", "OUTPUTS", "expand", "read_jobs", "check_job", "command_parser", "command_job", "job_argv",
           "run_command"]

#: commands a batch can run -> (their arguments' add_arguments, run_<cmd>)
COMMANDS = {
    "bake": (arguments.bake.add_arguments, bake.run_bake),
    "render": (arguments.render.add_arguments, render.run_render),
    "compare": (arguments.compare.add_arguments, compare.run_compare),
    "mc": (arguments.mc.add_arguments, mc.run_mc),
    "profile": (arguments.profile.add_arguments, profile.run_profile),
}
#: output options per command (file names inside the job's folder) and the default of the required one
OUTPUTS = {
    "bake": {"out": "bake.ply", "npz": None, "texture": None},
    "render": {"out": "render"},
    "compare": {"out": "."},
    "mc": {"out": "mc.ply", "npz": None, "summary": None},
    "profile": {"csv": "profile.csv", "plot": None},
}
#: options a job may not set: the batch decides them for every job
BATCH_ONLY = {"scheduler", "workers", "quiet", "q", "verbose", "help"}


class _JobParser(argparse.ArgumentParser):
    def error(self, message):
        raise JobFileError(message)


def command_parser(command: str) -> argparse.ArgumentParser:
    """The argument parser of ``meshshade <command>`` (with ``--quiet``), raising :class:`JobFileError`."""
    add, _run = COMMANDS[command]
    p = _JobParser(prog=f"meshshade {command}", add_help=False)
    p.add_argument("--quiet", "-q", action="store_true")
    add(p)
    return p


def _option_kinds(command: str) -> dict:
    """option name (dashes) -> 'flag' | 'append' | 'value' | 'positional' for ``command``."""
    kinds = {}
    for a in command_parser(command)._actions:
        if not a.option_strings:
            kinds[a.dest.replace("_", "-")] = "positional"
            continue
        name = max(a.option_strings, key=len).lstrip("-")
        kinds[name] = ("flag" if a.nargs == 0 else "append" if isinstance(a, argparse._AppendAction) else "value")
    return kinds


def _scalar_text(value, where: str) -> str:
    if isinstance(value, bool) or not isinstance(value, (str, int, float)):
        raise JobFileError(f"{where} must be a string or a number, got {value!r}")
    return str(value)


def job_argv(job: Job, folder) -> list[str]:
    """The command line that runs ``job`` with its outputs inside ``folder``."""
    kinds = _option_kinds(job.command)
    outs = OUTPUTS[job.command]
    argv = [job.command, "--quiet"]
    for key, value in job.options.items():
        kind = kinds[key]
        if key in outs:
            value = str(Path(folder) / value)
        if kind == "positional":
            argv.append(str(value))
        elif kind == "flag":
            if value:
                argv.append(f"--{key}")
        elif kind == "append":
            argv.extend(f"--{key}={_scalar_text(v, key)}" for v in (value if isinstance(value, list) else [value]))
        else:
            argv.append(f"--{key}={_scalar_text(value, key)}")
    return argv


def run_command(job: Job, folder) -> None:
    """Run ``job`` (a meshshade command) in this process, its outputs into ``folder``: the same parser and code as
    ``meshshade <command>`` on the command line, in one output transaction (the :class:`Job`'s ``execute``)."""
    args = command_parser(job.command).parse_args(job_argv(job, folder)[1:])
    _add, run = COMMANDS[job.command]
    with output_transaction():
        run(args)


def command_job(name: str, command: str, **options) -> Job:
    """A :class:`Job` running ``meshshade <command>`` with ``options`` (names with dashes or underscores, as in a
    job file; outputs are file names in the job's folder), checked like a job file's."""
    if command not in COMMANDS:
        raise JobFileError(f"job {name}: unknown command {command!r} (one of {', '.join(COMMANDS)})")
    job = Job(name=name, command=command, options=_normalise(command, _dashed(options, f"job {name}"),
                                                               f"job {name}", Path(".")), execute=run_command)
    check_job(job)
    return job


def _normalise(command: str, options: dict, where: str, base: Path) -> dict:
    """Options with dashes, inputs resolved against ``base``, outputs defaulted and checked; an option's former
    spelling (``near-field``) becomes its new one (``source-model``), with a warning."""
    kinds = _option_kinds(command)
    renamed = deprecated_aliases(command_parser(command))
    out: dict = {}
    for raw, value in options.items():
        key = str(raw)
        if key in renamed:
            warnings.warn(f"job file option {key} is deprecated; use {renamed[key]}", FutureWarning, stacklevel=2)
            key = renamed[key]
        if key in BATCH_ONLY:
            raise JobFileError(f"{where}: option {raw!r} is set for the whole batch, not per job")
        if key not in kinds:
            known = ", ".join(sorted(k for k in kinds if k not in BATCH_ONLY and k not in renamed))
            raise JobFileError(f"{where}: {command} has no option {raw!r} (it has: {known})")
        if key in out:
            raise JobFileError(f"{where}: option {raw!r} given twice")
        if kinds[key] == "flag":
            if not isinstance(value, bool):
                raise JobFileError(f"{where}: {key} is a flag: true or false, got {value!r}")
        elif kinds[key] == "append":
            values = value if isinstance(value, list) else [value]
            if not values:
                raise JobFileError(f"{where}: {key} is an empty list")
            value = [_scalar_text(v, f"{where}: {key}") for v in values]
            if key == "material" and len(value) == 1:
                value = value[0]        # one material as it was before the key was repeatable (same job hash)
        else:
            value = _scalar_text(value, f"{where}: {key}")
        beside = key in ("mesh", "radius-map") or (key == "albedo-map" and value not in ("mtl", "vertex"))
        if beside:                                                                           # beside the job file
            value = str((base / value).resolve()) if not Path(value).is_absolute() else value
        if key == "light":   # an environment map's file is relative to the job file, as the mesh
            value = [_resolve_map(v, base) for v in value]
        out[key] = value
    for key, default in OUTPUTS[command].items():
        if key not in out and default is not None:
            out[key] = default
        if key in out:
            name = str(out[key])
            if name != "." and (not name or "/" in name or "\\" in name or name in ("..",) or name.startswith(".")):
                raise JobFileError(f"{where}: {key} {name!r} must be a plain file name (it is written in the job's "
                                   "own folder)")
    return out


def _resolve_map(spec: str, base: Path) -> str:
    """``env:FILE...`` with a relative FILE resolved against ``base`` (where the file is, if the spec's optional
    fields are taken off); any other light spec as it is."""
    if not spec.lower().startswith("env:"):
        return spec
    rest = spec[4:]
    parts = rest.split(":")
    for k in range(len(parts), 0, -1):           # the longest head that names a file next to the job file
        head = ":".join(parts[:k])
        if head and not Path(head).is_absolute() and (base / head).is_file():
            return "env:" + ":".join([str((base / head).resolve()), *parts[k:]])
    return spec


def _job_name(command: str, options: dict, template: str | None, varied: dict, where: str) -> str:
    if template is not None:
        fields = {k.replace("-", "_"): _short(v) for k, v in {**options, **varied}.items()}
        try:
            name = str(template).format(**fields)
        except (KeyError, IndexError, ValueError) as exc:
            raise JobFileError(f"{where}: name template {template!r}: no option {exc} to fill it in") from None
    elif varied:
        name = "-".join([command] + [_short(v) for v in varied.values()])
    else:
        name = f"{command}-{hashlib.sha256(json.dumps(options, sort_keys=True).encode()).hexdigest()[:8]}"
    name = re.sub(r"[^A-Za-z0-9._=,+-]+", "_", name).strip("_.") or command
    if not NAME_PATTERN.match(name):
        raise JobFileError(f"{where}: job name {name!r} is not a usable folder name (letters, digits, . _ = , + -; "
                           "at most 120 characters)")
    return name


def _short(value) -> str:
    """A value as it reads in a job name: a path's stem, a list's items joined by '+'."""
    if isinstance(value, list):
        return "+".join(_short(v) for v in value)
    text = str(value)
    if "/" in text or "\\" in text or re.search(r"\.(obj|ply|off|stl|glb|gltf)$", text, re.I):
        return Path(text).stem
    return text


def check_job(job: Job) -> None:
    """Parse the job's command line with the command's own parser (outputs in a placeholder folder): unknown
    options, malformed numbers and missing required options are one-line :class:`JobFileError` naming the job."""
    if job.command not in COMMANDS:
        raise JobFileError(f"job {job.name}: unknown command {job.command!r} (one of {', '.join(COMMANDS)})")
    try:
        command_parser(job.command).parse_args(job_argv(job, "JOB")[1:])
    except JobFileError as exc:
        raise JobFileError(f"job {job.name}: {exc}") from None


def expand(spec: dict, base=".") -> list[Job]:
    """Jobs of a parsed job file (``{"defaults": {...}, "job": [...], "sweep": [...]}``), in file order (jobs,
    then each sweep's product in the order of its ``vary`` keys). Paths are relative to ``base``."""
    base = Path(base)
    if not isinstance(spec, dict):
        raise JobFileError("a job file is a table with [[job]] and [[sweep]] entries")
    unknown = set(spec) - {"defaults", "job", "sweep"}
    if unknown:
        raise JobFileError(f"unknown section(s) {', '.join(sorted(unknown))} (allowed: [defaults], [[job]], "
                           "[[sweep]])")
    defaults = spec.get("defaults", {})
    if not isinstance(defaults, dict):
        raise JobFileError("[defaults] must be a table of options")
    defaults = _dashed(defaults, "[defaults]")
    entries = [("job", e) for e in _entries(spec, "job")] + [("sweep", e) for e in _entries(spec, "sweep")]
    jobs: list[Job] = []
    used_defaults: set = set()
    for n, (kind, entry) in enumerate(entries, 1):
        where = f"{kind} {entry.get('name', '#' + str(n))}"
        entry = _dashed(entry, where)
        command = entry.pop("command", None)
        if command not in COMMANDS:
            raise JobFileError(f"{where}: command must be one of {', '.join(COMMANDS)}, got {command!r}")
        template = entry.pop("name", None)
        vary = entry.pop("vary", None) if kind == "sweep" else None
        if kind == "sweep":
            if not isinstance(vary, dict) or not vary:
                raise JobFileError(f"{where}: a sweep needs a [sweep.vary] table of option lists")
            vary = _dashed(vary, where + ": vary")
            for k, v in vary.items():
                if not isinstance(v, list) or not v:
                    raise JobFileError(f"{where}: vary.{k} must be a non-empty list of values")
                if k in entry:
                    raise JobFileError(f"{where}: option {k!r} is both fixed and varied")
        kinds = _option_kinds(command)
        fixed = {}
        for k, v in defaults.items():
            if k in kinds and k not in entry and (vary is None or k not in vary):
                fixed[k] = v
                used_defaults.add(k)
        fixed.update(entry)
        combos = [dict(zip(vary, values)) for values in itertools.product(*vary.values())] if vary else [{}]
        for combo in combos:
            options = _normalise(command, {**fixed, **combo}, where, base)
            shown = {k: options[k] for k in combo}
            name = _job_name(command, options, template, shown, where)
            jobs.append(Job(name=name, command=command, options=options, execute=run_command))
    unused = set(defaults) - used_defaults
    if unused and entries:
        raise JobFileError(f"[defaults]: no job's command has option(s) {', '.join(sorted(map(str, unused)))}")
    seen: dict = {}
    for job in jobs:
        if job.name in seen:
            raise JobFileError(f"two jobs are named {job.name!r}: give each job (or sweep name template) a unique "
                               "name")
        seen[job.name] = job
        check_job(job)
    if not jobs:
        raise JobFileError("the job file lists no [[job]] or [[sweep]]")
    return jobs


def _dashed(table: dict, where: str) -> dict:
    """``table`` with option names written with dashes (``cutoff_tol`` -> ``cutoff-tol``)."""
    out = {}
    for k, v in table.items():
        key = str(k).replace("_", "-")
        if key in out:
            raise JobFileError(f"{where}: option {k!r} given twice")
        out[key] = v
    return out


def _entries(spec: dict, key: str) -> list[dict]:
    value = spec.get(key, [])
    if isinstance(value, dict):
        value = [value]
    if not isinstance(value, list) or not all(isinstance(e, dict) for e in value):
        raise JobFileError(f"[[{key}]] entries must be tables")
    return value


def read_jobs(path) -> list[Job]:
    """The jobs of a TOML job file (see the module docstring); paths in it are relative to its folder."""
    path = Path(path)
    try:
        return expand(read_toml(path), base=path.parent)
    except JobFileError as exc:
        raise JobFileError(f"{path}: {exc}") from None
