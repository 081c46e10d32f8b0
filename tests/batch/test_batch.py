"""``meshshade batch`` on a real Dask LocalCluster (2 worker processes): a sweep gives what the same commands give
one by one, a re-run skips finished jobs, a failing job is reported while the rest finish, a worker killed during
a job is survived, and the pieces underneath (job files, job folders, reuse of geometry between jobs).
"""
from __future__ import annotations

import json
import os
import signal
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from meshshade import memo
from meshshade.batch import Job, JobFileError, open_client, run_batch, run_job
from meshshade.batch.runner import MANIFEST, RECORD
from meshshade.cli.jobs import command_job, expand, read_jobs
from meshshade.cli.main import main
from meshshade.geometry.procedural import icosphere
from meshshade.io import job_folder, read_baked_ply, remove_stale_parts, write_ply

JOB_FILE = """
[defaults]
material = "skin1"

[[job]]
name = "ball-mc"
command = "mc"
mesh = "ball.ply"
light = "directional:0,0,-1"
photons = 20000
seed = 7

[[job]]
name = "ball-render"
command = "render"
mesh = "ball.ply"
light = "directional:0,0,-1"
model = "curved"
width = 24
height = 24

[[sweep]]
command = "bake"
mesh = "ball.ply"
[sweep.vary]
model = ["dipole", "curved"]
light = ["directional:0,0,-1", ["directional:0,0,-1", "point:0,0,40"]]
"""


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    d = tmp_path_factory.mktemp("batch")
    V, F = icosphere(radius=10.0, subdivisions=2)
    write_ply(d / "ball.ply", V, F)
    (d / "jobs.toml").write_text(JOB_FILE)
    return d


def _manifest(out: Path) -> dict:
    return {r["name"]: r for r in map(json.loads, (out / MANIFEST).read_text().splitlines())}


class _CLI:
    """``meshshade ARGV`` in this process: (exit code, stdout, stderr) (as tests/cli/conftest.py's ``cli``)."""

    def __init__(self, capsys):
        self.capsys = capsys

    def run(self, argv):
        self.capsys.readouterr()
        rc = main([str(a) for a in argv])
        cap = self.capsys.readouterr()
        return rc, cap.out, cap.err


@pytest.fixture
def cli(capsys):
    return _CLI(capsys)


def _tree(d: Path) -> dict:
    return {str(p.relative_to(d)): (p.read_bytes() if p.is_file() else None) for p in sorted(d.rglob("*"))}


def _radiance(path):
    mesh, rad, info = read_baked_ply(path)
    return rad


# ------------------------------------------------------------------------------------------------ job files
def test_job_file_expands_sweeps_in_order_with_defaults_and_paths(scene):
    jobs = read_jobs(scene / "jobs.toml")
    assert [j.name for j in jobs] == [
        "ball-mc", "ball-render",
        "bake-dipole-directional_0,0,-1", "bake-dipole-directional_0,0,-1+point_0,0,40",
        "bake-curved-directional_0,0,-1", "bake-curved-directional_0,0,-1+point_0,0,40"]
    bake = jobs[3]
    assert bake.options["material"] == "skin1"                     # from [defaults]
    assert bake.options["mesh"] == str((scene / "ball.ply").resolve())   # relative to the job file
    assert bake.options["light"] == ["directional:0,0,-1", "point:0,0,40"]
    assert bake.options["out"] == "bake.ply"                        # the command's default output
    assert "photons" not in bake.options                            # only mc has it
    assert jobs[0].options["photons"] == "20000"
    assert len({j.param_hash for j in jobs}) == len(jobs)


def test_sweep_name_template():
    jobs = expand({"sweep": [{"command": "profile", "name": "p-{material}-{models}", "vary": {
        "material": ["skin1", "marble"], "models": ["dipole", "dipole,curved"]}}]})
    assert [j.name for j in jobs] == ["p-skin1-dipole", "p-skin1-dipole,curved", "p-marble-dipole",
                                      "p-marble-dipole,curved"]
    with pytest.raises(JobFileError, match="no option"):
        expand({"sweep": [{"command": "profile", "name": "p-{nope}", "vary": {"material": ["skin1"]}}]})


@pytest.mark.parametrize("spec, needle", [
    ({"job": [{"command": "bake", "mesh": "a.ply", "lihgt": "directional:0,0,-1"}]}, "has no option 'lihgt'"),
    ({"job": [{"command": "bak", "mesh": "a.ply"}]}, "command must be one of"),
    ({"job": [{"command": "bake", "light": "d"}]}, "required: mesh"),       # bake's own parser
    ({"job": [{"command": "bake", "mesh": "a.ply", "light": "directional:0,0,-1", "cutoff-tol": "x"}]},
     "cutoff-tol"),
    ({"job": [{"command": "bake", "mesh": "a.ply", "light": "d", "out": "../x.ply"}]}, "plain file name"),
    ({"job": [{"command": "mc", "mesh": "a.ply", "light": "d", "workers": 2}]}, "whole batch"),
    ({"job": [{"command": "bake", "mesh": "a.ply", "light": "d", "name": "x"},
              {"command": "bake", "mesh": "b.ply", "light": "d", "name": "x"}]}, "two jobs are named"),
    ({"sweep": [{"command": "bake", "mesh": "a.ply", "light": "d", "vary": {"light": ["e"]}}]},
     "both fixed and varied"),
    ({"sweep": [{"command": "bake", "mesh": "a.ply", "light": "d", "vary": {"model": []}}]}, "non-empty list"),
    ({"defaults": {"photons": 5}, "job": [{"command": "bake", "mesh": "a.ply", "light": "d"}]},
     "no job's command has"),
    ({"jobs": []}, "unknown section"),
    ({}, "lists no"),
])
def test_bad_job_files_are_one_line_errors_before_anything_runs(spec, needle):
    with pytest.raises(JobFileError) as e:
        expand(spec)
    assert needle in str(e.value) and "\n" not in str(e.value)


def test_bad_job_file_on_the_command_line_exits_2_and_writes_nothing(cli, tmp_path):
    (tmp_path / "jobs.toml").write_text('[[job]]\ncommand = "bake"\nmesh = "a.ply"\nlihgt = "directional:0,0,-1"\n')
    (tmp_path / "broken.toml").write_text("[[job]\n")
    before = _tree(tmp_path)
    for name, needle in (("jobs.toml", "has no option 'lihgt'"), ("broken.toml", "not valid TOML"),
                         ("absent.toml", "job file not found")):
        rc, out, err = cli.run(["batch", tmp_path / name, "--out", tmp_path / "res"])
        assert rc == 2 and "Traceback" not in err, err
        assert err.count("\n") == 1 and err.startswith("meshshade: error: ") and needle in err, err
        assert _tree(tmp_path) == before


# ------------------------------------------------------------------------------------------------ folders
def test_job_folder_appears_whole_or_not_at_all(tmp_path):
    final = tmp_path / "job"
    with pytest.raises(RuntimeError):
        with job_folder(final) as tmp:
            (tmp / "a.txt").write_text("half")
            raise RuntimeError("boom")
    assert list(tmp_path.iterdir()) == []
    with job_folder(final) as tmp:
        (tmp / "a.txt").write_text("one")
        assert not final.exists()                     # nothing visible until the block ends
    assert (final / "a.txt").read_text() == "one"
    with pytest.raises(KeyboardInterrupt):
        with job_folder(final) as tmp:
            (tmp / "a.txt").write_text("two")
            raise KeyboardInterrupt
    assert (final / "a.txt").read_text() == "one"     # an interrupted re-run leaves the old result whole
    with job_folder(final) as tmp:
        (tmp / "b.txt").write_text("three")
    assert sorted(p.name for p in final.iterdir()) == ["b.txt"]   # replaced as a whole on success
    assert [p.name for p in tmp_path.iterdir()] == ["job"]
    (tmp_path / ".job.part-0123abcd").mkdir()        # as a killed worker leaves it
    (tmp_path / ".other.part-0123abcd").mkdir()
    assert remove_stale_parts(tmp_path, {"job"}) == [".job.part-0123abcd"]
    assert sorted(p.name for p in tmp_path.iterdir()) == [".other.part-0123abcd", "job"]


# ------------------------------------------------------------------------------------------------ one job
def test_run_job_records_outputs_and_a_failure_is_data_not_an_exception(scene, tmp_path):
    ok = command_job("one", "bake", mesh=str(scene / "ball.ply"), material="marble", light="directional:0,0,-1",
                     model="dipole")
    rec = run_job(ok, tmp_path)
    assert rec["status"] == "ok", rec
    assert set(rec["outputs"]) == {"bake.ply"} and len(rec["outputs"]["bake.ply"]) == 64
    assert json.loads((tmp_path / "one" / RECORD).read_text())["param_hash"] == ok.param_hash
    assert {"meshshade", "numpy", "numba", "distributed"} <= set(rec["versions"])
    bad = command_job("two", "bake", mesh=str(scene / "ball.ply"), material="marble", light="directional:0,0,-1",
                      cutoff_tol=5)                   # parses, refused by bake's own checks at run time
    rec = run_job(bad, tmp_path)
    assert rec["status"] == "failed" and "cutoff" in rec["error"] and "\n" not in rec["error"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["one"]


def test_reuse_between_jobs_is_keyed_by_what_the_result_depends_on(scene, tmp_path):
    """A worker keeps mesh, curvature, scene and transport between jobs; a material or light change must still
    give the result of a fresh process (the bug this catches: a cache key missing the material)."""
    memo.clear()
    common = dict(mesh=str(scene / "ball.ply"), model="auto", light="directional:0,0,-1")
    jobs = [command_job("skin", "bake", material="skin1", **common),
            command_job("marble", "bake", material="marble", **common),
            command_job("marble-2", "bake", material="marble", **{**common, "light": "directional:0,1,-1"})]
    recs = [run_job(j, tmp_path / "warm") for j in jobs]
    assert all(r["status"] == "ok" for r in recs), recs
    assert recs[1]["reused"].get("mesh reused") == 1 and recs[1]["reused"].get("curvature reused") == 1
    assert recs[2]["reused"].get("transport reused") == 1        # same mesh, material and model: another light
    for job in jobs:
        memo.clear()
        cold = run_job(job, tmp_path / "cold")
        assert cold["reused"].get("transport reused") is None
        warm = _radiance(tmp_path / "warm" / job.name / "bake.ply")
        np.testing.assert_array_equal(_radiance(tmp_path / "cold" / job.name / "bake.ply"), warm)
    assert not np.allclose(_radiance(tmp_path / "warm/skin/bake.ply"), _radiance(tmp_path / "warm/marble/bake.ply"))


def test_a_job_can_be_any_picklable_function(tmp_path):
    rec = run_job(Job("custom", "sum", {"n": 4}, execute=_write_sum), tmp_path)
    assert rec["status"] == "ok" and (tmp_path / "custom" / "sum.txt").read_text() == "6"
    with pytest.raises(JobFileError):
        Job("../up", "sum", {}, execute=_write_sum)
    with pytest.raises(JobFileError):
        Job("x", "sum", {"a": object()}, execute=_write_sum)


def _write_sum(job, folder):
    (Path(folder) / "sum.txt").write_text(str(sum(range(job.options["n"]))))


# ------------------------------------------------------------------------------------------------ on Dask
@pytest.mark.slow   # 25-35 s; the other Dask tests here (a killed worker, Ctrl-C) keep the cluster in CI
def test_sweep_on_two_workers_equals_the_commands_run_one_by_one_and_a_rerun_skips_all(scene, tmp_path, cli,
                                                                                     dask_client):
    jobs = read_jobs(scene / "jobs.toml")
    out = tmp_path / "res"
    res = run_batch(jobs, out, client=dask_client, progress=False, quiet=True)
    assert res.ok and sorted(res.ran) == sorted(j.name for j in jobs) and not res.skipped
    man = _manifest(out)
    assert all(r["status"] == "ok" for r in man.values())
    assert len({r["worker"] for r in man.values()}) == 2              # both workers took jobs
    assert sorted(p.name for p in out.iterdir()) == sorted([MANIFEST, *man])   # no .part folders
    ball = scene / "ball.ply"
    # the same commands by hand, in this process (2 numba threads here, 1 in each worker)
    solo = tmp_path / "solo"
    solo.mkdir()
    runs = {
        "bake-curved-directional_0,0,-1+point_0,0,40": (["bake", ball, "--material", "skin1", "--model", "curved",
                                                         "--light", "directional:0,0,-1", "--light", "point:0,0,40",
                                                         "--out", solo / "b1.ply"], "bake.ply", solo / "b1.ply"),
        "bake-dipole-directional_0,0,-1": (["bake", ball, "--material", "skin1", "--model", "dipole", "--light",
                                            "directional:0,0,-1", "--out", solo / "b2.ply"], "bake.ply",
                                           solo / "b2.ply"),
        "ball-mc": (["mc", ball, "--material", "skin1", "--light", "directional:0,0,-1", "--photons", "20000",
                     "--seed", "7", "--out", solo / "m.ply"], "mc.ply", solo / "m.ply"),
    }
    for name, (argv, output, path) in runs.items():
        rc, _, err = cli.run([*argv, "--quiet"])
        assert rc == 0, err
        np.testing.assert_allclose(_radiance(out / name / output), _radiance(path), rtol=1e-6, atol=0)
    rc, _, err = cli.run(["render", ball, "--material", "skin1", "--model", "curved", "--light",
                          "directional:0,0,-1", "--width", "24", "--height", "24", "--out", solo / "r", "--quiet"])
    assert rc == 0, err
    assert (out / "ball-render" / "render.png").read_bytes() == (solo / "r.png").read_bytes()

    stamps = {p: p.stat().st_mtime_ns for p in out.rglob("*") if p.is_file() and p.name != MANIFEST}
    again = run_batch(read_jobs(scene / "jobs.toml"), out, client=dask_client, progress=False, quiet=True)
    assert again.ok and again.ran == [] and sorted(again.skipped) == sorted(man)
    assert _manifest(out) == man                                      # the records of the first run are kept
    assert {p: p.stat().st_mtime_ns for p in stamps} == stamps        # nothing was rewritten

    changed = [j if j.name != "ball-mc" else Job(j.name, j.command, {**j.options, "seed": "8"}, j.execute)
               for j in jobs]
    third = run_batch(changed, out, client=dask_client, progress=False, quiet=True)
    assert third.ran == ["ball-mc"]                                   # changed options: run again, replaced
    assert _manifest(out)["ball-mc"]["options"]["seed"] == "8"
    assert not np.array_equal(_radiance(out / "ball-mc/mc.ply"), _radiance(solo / "m.ply"))


def test_a_failing_job_is_one_line_and_the_rest_finish(scene, tmp_path, dask_client, capsys):
    spec = {"job": [
        {"name": "good", "command": "bake", "mesh": "ball.ply", "material": "skin1", "light": "directional:0,0,-1",
         "model": "dipole"},
        {"name": "no-mesh", "command": "bake", "mesh": "missing.ply", "material": "skin1",
         "light": "directional:0,0,-1"},
        {"name": "bad-value", "command": "bake", "mesh": "ball.ply", "material": "skin1",
         "light": "directional:0,0,-1", "cutoff-tol": 5},
    ]}
    out = tmp_path / "res"
    res = run_batch(expand(spec, base=scene), out, client=dask_client, progress=False)
    err = capsys.readouterr().err
    assert sorted(res.failed) == ["bad-value", "no-mesh"] and not res.ok
    lines = [ln for ln in err.splitlines() if "failed" in ln]
    assert len(lines) == 2 and all(ln.startswith("meshshade: batch: job ") for ln in lines), err
    assert "Traceback" not in err
    man = _manifest(out)
    assert man["good"]["status"] == "ok"
    assert "mesh file not found" in man["no-mesh"]["error"] and man["no-mesh"]["outputs"] == {}
    assert sorted(p.name for p in out.iterdir()) == ["good", MANIFEST]
    # a re-run retries the failures only (they fail again) and keeps the good job
    again = run_batch(expand(spec, base=scene), out, client=dask_client, progress=False, quiet=True)
    assert sorted(again.ran) == ["bad-value", "no-mesh"] and again.skipped == ["good"]


def test_batch_command_line_exit_code_1_when_a_job_failed(scene, tmp_path, cli):
    (tmp_path / "jobs.toml").write_text(
        f'[[job]]\nname = "ok"\ncommand = "profile"\nmaterial = "skin1"\n'
        f'[[job]]\nname = "bad"\ncommand = "bake"\nmaterial = "skin1"\nmesh = "{scene / "missing.ply"}"\n'
        'light = "directional:0,0,-1"\n')
    rc, out, err = cli.run(["batch", tmp_path / "jobs.toml", "--out", tmp_path / "res", "--workers", "1"])
    assert rc == 1, err
    assert "meshshade: batch: job bad failed: mesh file not found" in err and "Traceback" not in err
    assert "1 finished now" in out and "1 failed" in out
    assert (tmp_path / "res" / "ok" / "profile.csv").is_file() and not (tmp_path / "res" / "bad").exists()
    rc, out, err = cli.run(["batch", tmp_path / "jobs.toml", "--out", tmp_path / "res", "--dry-run"])
    assert rc == 0 and "ok\tprofile\tdone" in out and "bad\tbake\tto run" in out


def test_a_worker_killed_during_a_job_costs_only_that_job(scene, tmp_path, cli):
    """Kill the worker process running the Monte Carlo job half-way: Dask re-runs the task on a worker, the job's
    result equals an undisturbed run (same seed), and no partial folder is left."""
    mc = {"name": "long-mc", "command": "mc", "mesh": "ball.ply", "material": "skin1",
          "light": "directional:0,0,-1", "photons": 150_000, "seed": 3}
    quick = {"name": "quick", "command": "profile", "material": "skin1"}
    jobs = expand({"job": [mc, quick]}, base=scene)
    out = tmp_path / "res"
    outcome = {}
    killed = []
    with open_client(workers=2, quiet=True) as client:
        runner = threading.Thread(target=lambda: outcome.setdefault(
            "res", run_batch(jobs, out, client=client, progress=False, quiet=True)))
        runner.start()
        key = next(f"meshshade-job-{j.name}-{j.param_hash}" for j in jobs if j.name == "long-mc")
        deadline = time.monotonic() + 60
        while not killed and time.monotonic() < deadline:
            started = out.is_dir() and any(p.name.startswith(".long-mc.part-") for p in out.iterdir())
            where = [w for w, keys in client.processing().items() if key in keys]
            if started and where:
                pid = client.run(os.getpid, workers=where)[where[0]]
                os.kill(pid, signal.SIGKILL)
                killed.append(pid)
            time.sleep(0.05)
        runner.join(120)
    assert killed, "the job never started"
    res = outcome["res"]
    assert res.ok, res.records
    rec = _manifest(out)["long-mc"]
    assert rec["status"] == "ok" and not rec["worker"].endswith(f":{killed[0]}")
    assert sorted(p.name for p in out.iterdir()) == sorted(["long-mc", "quick", MANIFEST])
    rc, _, err = cli.run(["mc", scene / "ball.ply", "--material", "skin1", "--light", "directional:0,0,-1",
                          "--photons", "150000", "--seed", "3", "--out", tmp_path / "ref.ply", "--quiet"])
    assert rc == 0, err
    np.testing.assert_allclose(_radiance(out / "long-mc" / "mc.ply"), _radiance(tmp_path / "ref.ply"), rtol=1e-6)


def test_the_example_job_file_is_valid():
    jobs = read_jobs(Path(__file__).resolve().parents[2] / "examples" / "sweep.toml")
    assert len(jobs) == 10 and all(Path(j.options["mesh"]).is_file() for j in jobs if "mesh" in j.options)


def test_ctrl_c_stops_the_batch_leaving_finished_jobs_whole_and_no_partial_folder(scene, tmp_path):
    """SIGINT to ``meshshade batch`` while a long job runs: exit code 130, one line, the finished job's folder
    and the manifest kept (a re-run skips it), no ``.part`` folder of the interrupted one."""
    import subprocess
    import sys

    (tmp_path / "jobs.toml").write_text(
        f'[[job]]\nname = "first"\ncommand = "profile"\nmaterial = "skin1"\n'
        f'[[job]]\nname = "long"\ncommand = "mc"\nmaterial = "skin1"\nmesh = "{scene / "ball.ply"}"\n'
        f'light = "directional:0,0,-1"\nphotons = 5e6\n')
    out = tmp_path / "res"
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[2]))
    proc = subprocess.Popen([sys.executable, "-m", "meshshade.cli", "batch", tmp_path / "jobs.toml", "--out", out,
                             "--workers", "2"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and not ((out / "first").is_dir() and any(
            p.name.startswith(".long.part-") for p in out.iterdir())):
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    err = err.decode()
    assert proc.returncode == 130, err
    assert "Traceback" not in err and err.strip().splitlines()[-1].startswith("meshshade: interrupted"), err
    assert sorted(p.name for p in out.iterdir()) == ["first", MANIFEST]
    assert _manifest(out)["first"]["status"] == "ok"


def test_a_texture_bake_job_writes_its_files_in_its_folder(scene, tmp_path):
    job = command_job("tex", "bake", mesh=str(scene / "ball.ply"), material="skin1", light="directional:0,0,-1",
                      texture="ball.exr", texture_size=32)
    rec = run_job(job, tmp_path)
    assert rec["status"] == "ok", rec
    assert {"bake.ply", "ball.exr", "ball.png", "ball.obj"} <= set(rec["outputs"])   # the PLY has no UVs: atlas
    assert {p.name for p in (tmp_path / "tex").iterdir()} >= {"bake.ply", "ball.exr", "ball.png", "ball.obj"}
