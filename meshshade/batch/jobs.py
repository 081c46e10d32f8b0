"""What a batch runs: a :class:`Job` is a name (its folder), a command label, JSON-ready options and the picklable
function that writes its outputs into a folder.

``meshshade batch`` builds its jobs from a TOML job file (:mod:`meshshade.cli.jobs`: each job is one meshshade
command, ``execute=meshshade.cli.jobs.run_command``); from Python, any picklable ``execute(job, folder)`` works,
e.g. a custom bake loop, and gets the same folders, manifest, re-run and retry behaviour.
"""
from __future__ import annotations

import hashlib
import json
import re
from dataclasses import dataclass, field
from typing import Callable

from meshshade.errors import MeshshadeError

__all__ = ["Job", "JobFileError", "NAME_PATTERN"]

#: a job's name is its folder's name
NAME_PATTERN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._=,+-]{0,119}$")


class JobFileError(MeshshadeError):
    """A job file (or a job given to the API) that cannot be run: one line naming the job and the problem."""


@dataclass(frozen=True)
class Job:
    """One unit of a batch.

    name : the job's folder under the batch's output folder (letters, digits and ``. _ = , + -``);
    command : what it runs (a label in the manifest; for command jobs, the meshshade subcommand);
    options : JSON-ready dict; with ``command`` it identifies the result (:attr:`param_hash`): a re-run skips a
        finished job only when these are unchanged;
    execute : ``execute(job, folder)``, a module-level function (it travels to the workers by reference), writing
        every output into ``folder`` and raising on failure.
    """

    name: str
    command: str
    options: dict = field(default_factory=dict)
    execute: Callable | None = None

    def __post_init__(self):
        if not isinstance(self.name, str) or not NAME_PATTERN.match(self.name):
            raise JobFileError(f"job name {self.name!r} is not a usable folder name (letters, digits, . _ = , + -; "
                               "at most 120 characters, not starting with . or -)")
        if not callable(self.execute):
            raise JobFileError(f"job {self.name}: execute must be a function execute(job, folder)")
        try:
            json.dumps(self.options, sort_keys=True)
        except (TypeError, ValueError):
            raise JobFileError(f"job {self.name}: options must be JSON values (strings, numbers, lists, tables)") \
                from None

    def params(self) -> dict:
        """What identifies the job's result: command and options."""
        return {"command": self.command, "options": self.options}

    @property
    def param_hash(self) -> str:
        """First 16 hex digits of the SHA-256 of :meth:`params` as sorted JSON."""
        return hashlib.sha256(json.dumps(self.params(), sort_keys=True).encode()).hexdigest()[:16]
