"""Experiment: one home for a run's choices, checked once, recorded as plain data."""
import json
from dataclasses import fields, replace
from pathlib import Path

import pytest

from analyses.cli import build_parser
from analyses.commands.options import EXPERIMENT_OPTIONS, experiment_from_args
from analyses.experiment import Experiment
from analyses.paper_study import PAPER_EXPERIMENT


@pytest.mark.parametrize("field, value", [
    ("scene", 3), ("size", 0), ("size", 2.0), ("workload", "fast"), ("kd", "bvh"), ("max_depth", 0),
    ("max_depth", 65), ("mappings", ()), ("mappings", ("S", "S")), ("mappings", ("zigzag",)),
    ("n_processes", ()), ("n_processes", (2, 0)), ("hierarchy", "alpha9"), ("layout", "sparse"),
    ("cost", "cray"), ("n_cpus", 0), ("background", -1), ("cache_dir", 5), ("dask", " "),
    ("memory_budget", 1 << 20), ("progress", "yes"),
])
def test_each_bad_field_is_refused_by_name(field, value):
    """Fails if a field's check is dropped, e.g. deleting the ``require_int("Experiment.size", ...)`` line."""
    with pytest.raises(ValueError, match=rf"Experiment\.{field}"):
        Experiment(**{field: value})


def test_counts_are_kept_sorted_and_distinct():
    """Fails if ``__post_init__`` stored ``n_processes`` as given (mutation: ``counts = tuple(counts)``)."""
    assert Experiment(n_processes=(8, 2, 8)).n_processes == (2, 8)
    assert Experiment(n_processes=4).n_processes == (4,)


def test_parameters_are_plain_data_and_follow_replace():
    """Fails if ``as_parameters`` records a field from another one (mutation: ``"background_load": self.n_cpus``)
    or leaves an object in (mutation: ``"hierarchy": self.hierarchy_object()``)."""
    base = Experiment(scene="tetra", size=64, background=0, n_cpus=4, mappings=("S", "db"))
    varied = replace(base, background=8, cost="modern")
    recorded = json.loads(json.dumps(varied.as_parameters()))
    assert recorded["background_load"] == 8 and recorded["n_cpus"] == 4
    assert recorded["cost"]["name"] == "modern" and recorded["mappings"] == ["S", "DB"]
    assert recorded["hierarchy"]["name"] == "alpha21164" and recorded["kd"] == "sah"
    assert json.loads(json.dumps(base.as_parameters()))["background_load"] == 0
    # what changes no result is not recorded
    assert not {"cache_dir", "dask", "memory_budget", "progress"} & set(recorded)
    # platform and frame_buffer_bytes are recorded only when set (tests/test_platforms.py), so outputs without one are unchanged;
    # spp and seed only for a path-traced workload (the others' records stay as they were)
    left_out = {"cache_dir", "dask", "memory_budget", "progress", "background", "platform", "spp", "seed",
                "frame_buffer_bytes", "interleave_cycles"}  # interleave_cycles: in the platform record
    assert set(recorded) == {field.name for field in fields(Experiment)} - left_out | {"background_load"}
    traced = replace(base, workload="pathtrace", spp=4, seed=9).as_parameters()
    assert (traced["spp"], traced["seed"]) == (4, 9)


def _defaults(argv):
    args = build_parser().parse_args(argv)
    return args, {field: getattr(args, option) for option, field in EXPERIMENT_OPTIONS.items()
                  if getattr(args, option, None) is not None}


@pytest.mark.parametrize("command, base", [("report", Experiment()), ("paper", PAPER_EXPERIMENT)])
def test_command_line_defaults_are_the_experiments(command, base):
    """The parent parsers must hold no default of their own: each equals its Experiment's.

    Fails if an option's default drifts, e.g. ``--cost`` defaulting to ``"modern"`` in
    ``model_options`` or ``--background`` to 3 in the report's ``machine_options``.
    """
    args, given = _defaults([command])
    assert given, "no experiment option found"
    for field, value in given.items():
        expected = getattr(base, field)
        assert (tuple(value) if isinstance(value, list) else value) == expected, field
    built = experiment_from_args(args, base, progress=base.progress)
    if command == "report":
        built = replace(built, n_processes=tuple(range(1, args.max_processes + 1)))
    assert built == base


def test_options_replace_the_base():
    """Fails if ``experiment_from_args`` skips an option (mutation: dropping ``"cpus": "n_cpus"``)."""
    args, _ = _defaults(["report", "tetra", "--size", "32", "--cpus", "4", "--background", "0", "--mappings", "S",
                         "R", "--processes", "2", "--cache", "somewhere", "--memory-budget", "1024"])
    built = experiment_from_args(args)
    assert (built.scene, built.size, built.n_cpus, built.background) == ("tetra", 32, 4, 0)
    assert built.mappings == ("S", "R") and built.n_processes == (2,) and built.memory_budget == 1 << 30
    assert Path(built.cache_dir) == Path("somewhere")


def test_a_whatif_study_holds_its_experiment(tmp_path):
    """A study file and the options reach the base experiment; nothing else is declared twice.

    Fails if the file may not set the workload (mutation: dropping ``"workload"`` from
    ``whatif.BASE_FIELDS``) or if the options replace the report's choices instead of the study's
    (mutation: ``experiment_from_args(args)`` without ``study.experiment`` in ``build_study``).
    """
    from analyses.commands.whatif import build_study
    from analyses.whatif import BUILTIN, WHATIF_EXPERIMENT, WhatIf, load_study_file

    path = tmp_path / "study.toml"
    path.write_text('scene = "tetra"\nworkload = "study1997"\nmemory_budget = 1073741824\nn_processes = 2\n'
                    '[grid]\nmemory_latency = [40, 80]\n')
    study = load_study_file(path)
    assert study.experiment == replace(WHATIF_EXPERIMENT, scene="tetra", workload="study1997",
                                       memory_budget=1 << 30, n_processes=(2,))
    assert study.n_processes == 2 and study.size == WHATIF_EXPERIMENT.size
    with pytest.raises(ValueError, match="one process count"):
        WhatIf(experiment=replace(WHATIF_EXPERIMENT, n_processes=(2, 4)), grid={"memory_latency": [40]})
    args = build_parser().parse_args(["whatif", "latency", "--workload", "study1997", "--processes", "3"])
    built = build_study(args)
    assert built.grid == BUILTIN["latency"].grid
    assert built.experiment == replace(WHATIF_EXPERIMENT, workload="study1997", n_processes=(3,),
                                       progress=built.experiment.progress)


def test_the_verdict_judges_the_study_machines_count_else_the_largest():
    """Fails if the count is not looked for (mutation: ``return max(counts)``) or is another machine's."""
    from analyses.verdict import VERDICT_PROCESSES, verdict_process_count
    from coherence.simulation import Machine

    assert VERDICT_PROCESSES == Machine().n_cpus == 8
    assert verdict_process_count([1, 2, 8, 16]) == 8
    assert verdict_process_count([1, 2, 4]) == 4
