"""Former spellings keep working for a release, each with one deprecation line (issue 32, "names that say one
thing"): ``--near-field`` -> ``--source-model`` (bake, render, compare, profile, bench; batch-file key ``near-field``),
the API keyword ``near_field=`` -> ``source_model=``, ``far_field="direct"`` -> ``"pairwise"``,
``far_geodesic="cluster"`` -> ``"shared"`` and the Monte Carlo ``engine="direct"`` -> ``"fused"``."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

from meshshade.cli.jobs import command_job, expand
from meshshade.cli.main import build_parser, main
from meshshade.errors import MeshshadeError
from meshshade.materials import Material
from meshshade.montecarlo.simulation import check_mc_options
from meshshade.montecarlo.walks import check_engine
from meshshade.profiles import Shape, profile_rows, reflectance_profile
from meshshade.transport import BakeOptions, SurfaceOptions
from meshshade.transport.baking import check_bake_options

WARNING = "meshshade: warning: --near-field is deprecated; use --source-model"
SKIN = Material(0.74, 0.032, 1.3)


@pytest.mark.parametrize("argv", [
    ["bake", "m.ply", "--material", "skin1", "--light", "directional:0,0,-1"],
    ["render", "m.ply", "--material", "skin1", "--light", "directional:0,0,-1", "--out", "r"],
    ["compare", "m.ply", "--material", "skin1", "--light", "directional:0,0,-1", "--out", "c"],
    ["profile", "--material", "skin1"],
    ["bench", "--out", "b"],
], ids=lambda a: a[0])
def test_the_old_option_still_sets_the_source_model_and_says_so_once(argv, capsys):
    parser = build_parser()
    new = parser.parse_args(argv + ["--source-model", "beam"])
    assert capsys.readouterr().err == ""
    old = parser.parse_args(argv + ["--near-field", "beam"])
    assert old.source_model == new.source_model == "beam" and not hasattr(old, "near_field")
    assert capsys.readouterr().err.splitlines() == [WARNING]
    # unset, the new option's default holds (the former spelling adds none of its own)
    assert parser.parse_args(argv).source_model == {"profile": "point", "bench": "point"}.get(argv[0])
    assert "--source-model" in _help(parser, argv[0]) and "--near-field" not in _help(parser, argv[0])


def _help(parser, command) -> str:
    sub = next(a for a in parser._actions if getattr(a, "choices", None) and command in a.choices)
    return sub.choices[command].format_help()


def test_profile_with_the_old_option_gives_the_same_curves(tmp_path, capsys):
    common = ["profile", "--material", "skin1", "--models", "dipole", "--distances", "0.2,1", "--quiet"]
    assert main(common + ["--source-model", "beam", "--csv", str(tmp_path / "new.csv")]) == 0
    assert main(common + ["--near-field", "beam", "--csv", str(tmp_path / "old.csv")]) == 0
    assert main(common + ["--source-model", "point", "--csv", str(tmp_path / "point.csv")]) == 0
    assert [line for line in capsys.readouterr().err.splitlines() if "warning" in line] == [WARNING]
    assert (tmp_path / "old.csv").read_text() == (tmp_path / "new.csv").read_text()
    assert (tmp_path / "old.csv").read_text() != (tmp_path / "point.csv").read_text()


def test_a_job_file_key_near_field_becomes_source_model_with_a_warning(tmp_path):
    with pytest.warns(FutureWarning, match="near-field is deprecated; use source-model"):
        job = command_job("p", "profile", material="skin1", near_field="beam")
    assert job.options.get("source-model") == "beam" and "near-field" not in job.options
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        new = command_job("p", "profile", material="skin1", source_model="beam")
    assert new.param_hash == job.param_hash   # the same job, whichever spelling the file used
    spec = {"job": [{"command": "profile", "name": "a", "material": "skin1", "near-field": "beam"}]}
    with pytest.warns(FutureWarning, match="near-field"):
        (a,) = expand(spec, base=tmp_path)
    assert a.options["source-model"] == "beam"


def test_the_old_api_keyword_warns_and_gives_the_same_profile():
    s = np.array([0.2, 1.0])
    new = reflectance_profile(SKIN, s, model="dipole", source_model="beam")
    with pytest.warns(DeprecationWarning, match="near_field= is deprecated; use source_model="):
        old = reflectance_profile(SKIN, s, model="dipole", near_field="beam")
    np.testing.assert_array_equal(old, new)
    assert not np.array_equal(new, reflectance_profile(SKIN, s, model="dipole"))
    with pytest.warns(DeprecationWarning):
        rows = profile_rows(SKIN, s, models=["dipole"], shapes=[Shape.make("plane")], near_field=["point", "beam"])
    assert sorted({r["model"] for r in rows}) == ["dipole", "dipole+beam"]
    with pytest.warns(DeprecationWarning), pytest.raises(MeshshadeError, match="disagree"):
        reflectance_profile(SKIN, s, source_model="point", near_field="beam")


def test_former_option_values_of_the_bake_and_monte_carlo_warn_and_map():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        options = BakeOptions(model="dipole", surface=SurfaceOptions(far_field="pairwise", far_geodesic="shared",
                                                                     source_model="beam"))
        assert options.far_field == "pairwise"
        assert check_engine("fused") == "fused"
    with pytest.warns(DeprecationWarning, match="far_field='direct' is deprecated; use far_field='pairwise'"):
        assert SurfaceOptions(far_field="direct").far_field == "pairwise"
    with pytest.warns(DeprecationWarning, match="far_geodesic='cluster' is deprecated; use far_geodesic='shared'"):
        assert SurfaceOptions(far_geodesic="cluster").far_geodesic == "shared"
    with pytest.raises(MeshshadeError, match="beam source model"):
        BakeOptions(model="volume", surface=SurfaceOptions(source_model="point"))
    with pytest.warns(DeprecationWarning, match="check_bake_options is deprecated"):   # the former checker
        assert check_bake_options("dipole", far_field="direct") == "pairwise"
    with pytest.warns(DeprecationWarning, match="check_bake_options is deprecated"):
        with pytest.raises(MeshshadeError, match="beam source model"):
            check_bake_options("volume", near_field="point")
    with pytest.warns(DeprecationWarning, match="engine='direct' is deprecated; use engine='fused'"):
        assert check_engine("direct") == "fused"
    with pytest.warns(DeprecationWarning, match="engine='direct'"):
        check_mc_options(1000, engine="direct")
    with pytest.raises(MeshshadeError, match="'auto', 'fused' or 'batched'"):
        check_engine("gpu")
