"""Platforms: presets validate, equal the tables of docs/platforms.md, and give a thread's share of shared levels."""
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from coherence.cost import COST_MODELS, MEASURED_CYCLES, get_cost_model
from coherence.mappings import get_mapping
from coherence.platforms import PLATFORMS, Platform, get_platform
from test_simulate_cli import saved  # noqa: F401  (the saved random trace fixture)

DOC = Path(__file__).resolve().parent.parent / "docs" / "platforms.md"


def doc_table(first_header: str) -> list[dict]:
    """The rows of the markdown table in docs/platforms.md whose header row starts with ``first_header``."""
    lines = DOC.read_text().splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith(f"| {first_header} |"))
    header = [cell.strip() for cell in lines[start].strip("|").split("|")]
    rows = []
    for line in lines[start + 2:]:
        if not line.startswith("|"):
            break
        rows.append(dict(zip(header, (cell.strip() for cell in line.strip("|").split("|")))))
    return rows


@pytest.mark.parametrize("name", list(PLATFORMS))
def test_each_preset_validates_and_counts_threads(name):
    """Each preset builds, its threads are cores x SMT, its cost model carries its name and clock
    and is the registered cost model of that name.
    Mutation: ``smt=1`` in zen4_7950x (then the docs table test fails too; here n_threads 16 != 32)."""
    platform = get_platform(name)
    machine = platform.hierarchy
    assert platform.name == name
    assert platform.n_threads == machine.n_cores * machine.smt
    assert platform.n_threads == {"zen4-7950x": 32, "xeon-8480": 112, "apple-m1": 4}[name]
    assert platform.cost.name == name and platform.cost.clock_hz == platform.clock_hz
    assert get_cost_model(name) == platform.cost
    assert {key: getattr(platform.cost, key) for key in MEASURED_CYCLES} == MEASURED_CYCLES
    assert platform.source == f"docs/platforms.md#{name}"
    assert f"## {name}" in DOC.read_text()


def test_machines_equal_the_docs_table():
    """Cores, SMT, cores per complex, clock and memory latency per platform, read from the page.
    Mutation: memory_latency=457 in zen4_7950x."""
    rows = doc_table("platform | cores")
    assert sorted(row["platform"] for row in rows) == sorted(PLATFORMS)
    for row in rows:
        platform = get_platform(row["platform"])
        machine = platform.hierarchy
        assert (machine.n_cores, machine.smt, machine.cores_per_complex) == \
            (int(row["cores"]), int(row["SMT"]), int(row["cores per complex"]))
        assert platform.clock_hz == pytest.approx(float(row["clock (GHz)"]) * 1e9, rel=1e-12)
        assert machine.hierarchy.memory_latency == float(row["memory latency (cycles)"])


def test_levels_equal_the_docs_table():
    """Every level's size, ways, line, sharing and latency, read from the page; no level missing.
    Mutation: latency 59 for the zen4-7950x L3 in zen4_7950x."""
    rows = doc_table("platform | level")
    seen = {}
    for row in rows:
        machine = get_platform(row["platform"]).hierarchy
        index = machine.hierarchy.level_names.index(row["level"])
        level = machine.hierarchy.levels[index]
        assert (level.size, level.ways, level.line_size, machine.shared_by[index], level.latency) == \
            (int(row["size"]), int(row["ways"]), int(row["line"]), row["shared by"], float(row["latency"])), row
        seen.setdefault(row["platform"], []).append(row["level"])
    assert seen == {name: get_platform(name).hierarchy.hierarchy.level_names for name in PLATFORMS}


def test_thread_view_gives_each_thread_its_share():
    """A level shared by k threads keeps 1/k of its bytes, in whole sets; private levels stay whole.
    Expected sizes by hand for zen4-7950x: L1 and L2 per core (2 threads): 16 KB and 512 KB; L3 per
    complex of 8 cores x 2 threads: 32 MB / 16 = 2 MB; apple-m1 L1 private 128 KB, L2 12 MB / 4 = 3 MB;
    xeon-8480 L3 105 MB / 112 = 960 KB (1024 sets of 15 ways).
    Mutation: divide by n_instances instead of threads_per_instance in thread_view."""
    sizes = {name: [level.size for level in get_platform(name).thread_view().levels] for name in PLATFORMS}
    assert sizes["zen4-7950x"] == [16 * 1024, 512 * 1024, 2 * 1024 * 1024]
    assert sizes["apple-m1"] == [128 * 1024, 3 * 1024 * 1024]
    assert sizes["xeon-8480"] == [24 * 1024, 1024 * 1024, 960 * 1024]
    view = get_platform("zen4-7950x").thread_view()
    assert view.name == "zen4-7950x-thread" and [level.latency for level in view.levels] == [4, 14, 58]
    assert view.memory_latency == 456


def test_default_processes_go_to_twice_the_threads_capped_at_32():
    """Mutation: drop the cap (xeon-8480 would go to 224)."""
    assert get_platform("apple-m1").default_processes() == tuple(range(1, 9))
    assert get_platform("zen4-7950x").default_processes() == tuple(range(1, 33))
    assert get_platform("xeon-8480").default_processes() == tuple(range(1, 33))


def test_bad_platforms_are_refused_by_name():
    """An unknown name lists the presets; a clock other than the cost model's is refused.
    Mutation: drop the clock comparison in Platform.__post_init__."""
    with pytest.raises(ValueError, match="unknown platform 'zen5'.*zen4-7950x, xeon-8480, apple-m1"):
        get_platform("zen5")
    zen = get_platform("zen4-7950x")
    with pytest.raises(ValueError, match="Platform.clock_hz"):
        replace(zen, clock_hz=4.5e9)
    with pytest.raises(ValueError, match="Platform.hierarchy"):
        replace(zen, hierarchy=zen.hierarchy.hierarchy)
    assert isinstance(get_platform(zen), Platform) and "modern" in COST_MODELS


def test_experiment_under_a_platform_takes_its_machine():
    """The Experiment's hierarchy, cost and CPUs are the platform's (a thread's share of each level, one CPU a
    hardware thread), its study runs on the platform's shared levels at Q = interleave_cycles, and its
    parameters say so; without a platform the parameters have no platform key, so every output is as before,
    and a Q other than the default is refused.
    The recorded hierarchy is the platform's whole levels (32 MB L3), not the thread view's shares.
    Mutation: return ``_hierarchy(self.hierarchy)`` in hierarchy_object whatever the platform; or record
    ``hierarchy_object()`` in as_parameters."""
    from analyses.experiment import Experiment
    from coherence.shared_run import DEFAULT_INTERLEAVE_CYCLES, SharedLevels

    zen = get_platform("zen4-7950x")
    experiment = Experiment(scene="tetra", size=8, platform="zen4-7950x")
    assert experiment.hierarchy_object() == zen.thread_view()
    assert experiment.cost_model() == zen.cost and experiment.machine().n_cpus == 32
    parameters = experiment.as_parameters()
    assert parameters["n_cpus"] == 32 and parameters["hierarchy"] == zen.hierarchy.hierarchy.to_dict()
    assert parameters["platform"]["name"] == "zen4-7950x" and parameters["platform"]["smt"] == 2
    assert "shared levels interleaved" in parameters["platform"]["shared_levels"]
    assert parameters["platform"]["interleave_cycles"] == DEFAULT_INTERLEAVE_CYCLES
    assert experiment.study_hierarchy() == SharedLevels(zen.hierarchy, DEFAULT_INTERLEAVE_CYCLES)
    finer = Experiment(scene="tetra", size=8, platform="zen4-7950x", interleave_cycles=10)
    assert finer.study_hierarchy().interleave_cycles == 10 and finer.as_parameters()["platform"]["interleave_cycles"] == 10
    assert "platform" not in Experiment(scene="tetra", size=8).as_parameters()
    with pytest.raises(ValueError, match="Experiment.interleave_cycles=10 applies to a platform"):
        Experiment(scene="tetra", size=8, interleave_cycles=10)
    with pytest.raises(ValueError, match="Experiment.page_placement='random'"):
        Experiment(scene="tetra", size=8, platform="zen4-7950x", page_placement="random")


@pytest.mark.parametrize("field, value", [("hierarchy", "modern"), ("cost", "modern"), ("n_cpus", 4)])
def test_experiment_refuses_a_platform_beside_what_it_sets(field, value):
    """Mutation: drop the ("n_cpus", STUDY_CPUS) pair from _check_platform (the n_cpus case passes)."""
    from analyses.experiment import Experiment

    with pytest.raises(ValueError, match=f"Experiment.platform apple-m1 sets .* leave Experiment.{field}"):
        Experiment(platform="apple-m1", **{field: value})
    with pytest.raises(ValueError, match="Experiment.platform: unknown platform 'm9'"):
        Experiment(platform="m9")


def test_simulate_under_a_platform(saved, capsys):
    """``coherence simulate --platform``: process counts 1..2 x hardware threads, the platform's CPUs,
    shared levels (Q from --interleave-cycles) and costs, the same runs as study() given them; with
    --hierarchy, --cost or --cpus a one-line error naming the option, and --interleave-cycles without
    --platform one too.
    Mutation: drop ``args.processes = list(platform.default_processes())`` in simulate.run."""
    import json

    from analyses.cli import main
    from coherence.shared_run import SharedLevels
    from coherence.simulation import Machine
    from coherence.studies import study

    trace, folder = saved
    m1 = get_platform("apple-m1")
    assert main(["simulate", str(folder), "--mapping", "S", "--platform", "apple-m1", "--interleave-cycles", "50",
                 "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert [run["n_processes"] for run in report["runs"]] == list(range(1, 9))
    expected = study(trace, ["S"], list(range(1, 9)), hierarchy=SharedLevels(m1.hierarchy, 50), cost=m1.cost,
                     machine=Machine(n_cpus=4), progress=False).runs
    assert [run["speedup_user"] for run in report["runs"]] == pytest.approx(expected["speedup_user"].tolist())
    assert [run["L1_coherence_misses"] for run in report["runs"]] == expected["L1_coherence_misses"].tolist()
    assert report["parameters"]["platform"]["name"] == "apple-m1"
    assert report["parameters"]["platform"]["interleave_cycles"] == 50
    assert report["parameters"]["shared_levels"]["interleave_cycles"] == 50
    assert report["parameters"]["machine"]["n_cpus"] == 4
    assert main(["simulate", str(folder), "--interleave-cycles", "50"]) == 2
    assert "--interleave-cycles applies to a platform's shared levels" in capsys.readouterr().err
    for option, value in (("--hierarchy", "modern"), ("--cost", "modern"), ("--cpus", "4")):
        assert main(["simulate", str(folder), "--platform", "apple-m1", option, value]) == 2
        err = capsys.readouterr().err
        assert f"--platform apple-m1 sets the hierarchy, the cost model and the CPUs; drop {option}" in err
        assert "Traceback" not in err


def test_whatif_under_a_platform_varies_the_platforms_machine():
    """A what-if study whose base has a platform configures each point from the platform's shared levels (the
    point's memory latency applied), cost model and hardware threads; a grid over what the platform sets is
    refused. Mutation: ``n_cpus = property(lambda self: self.experiment.n_cpus)`` in WhatIf (the CPUs stay 8)."""
    from analyses.whatif import WhatIf, configure

    m1 = get_platform("apple-m1")
    study = WhatIf.of("latency", {"memory_latency": [100, 200]}, scene="tetra", size=8, platform="apple-m1")
    shared, _, cost, machine, n_processes = configure(study, {"memory_latency": 200})
    assert shared.machine == replace(m1.hierarchy, hierarchy=replace(m1.hierarchy.hierarchy, memory_latency=200))
    assert shared.interleave_cycles == study.experiment.interleave_cycles
    assert cost == m1.cost and machine.n_cpus == 4 and n_processes == 8
    assert study.hierarchy == "apple-m1" and study.cost == "apple-m1"  # its shared levels run the points
    for key, values in (("n_cpus", [2, 4]), ("cost", ["modern"]), ("hierarchy", ["modern"])):
        with pytest.raises(ValueError, match=rf"grid\['{key}'\]: the platform apple-m1 sets"):
            WhatIf.of("bad", {key: values}, scene="tetra", size=8, platform="apple-m1")


def test_report_under_a_platform_takes_its_process_counts(tmp_path, capsys):
    """``coherence report --platform apple-m1`` simulates 1..8 processes (2 x its 4 threads) on 4 CPUs and
    records the platform; --max-processes still bounds the counts when given.
    Mutation: drop the platform branch that sets ``counts`` in report.run (counts 1..16)."""
    import json

    from analyses.cli import main

    common = ["report", "tetra", "--size", "8", "--mappings", "S", "--cache", str(tmp_path / "cache"), "--json"]
    assert main([*common, "--platform", "apple-m1", "--out", str(tmp_path / "a")]) == 0
    parameters = json.loads(capsys.readouterr().out)["parameters"]
    assert parameters["n_processes"] == list(range(1, 9)) and parameters["n_cpus"] == 4
    assert parameters["platform"]["name"] == "apple-m1"
    # summary.json carries the shared levels' counts per mapping at the verdict's count (mutation: drop
    # ``**shared`` in report_tables.summary)
    summary = json.loads((tmp_path / "a" / "summary.json").read_text())
    shared = summary["shared_levels"]["8"]["S"]
    assert set(shared) == {"L1", "L2"} and shared["L1"]["accesses"] > 0
    assert {"machine_misses", "coherence_misses", "false_sharing_misses", "coherence_invalidations"} <= set(shared["L2"])
    assert main([*common, "--platform", "apple-m1", "--max-processes", "3", "--out", str(tmp_path / "b")]) == 0
    assert json.loads(capsys.readouterr().out)["parameters"]["n_processes"] == [1, 2, 3]


def test_report_under_a_platform_maps_the_shared_runs_misses(tmp_path):
    """Under a platform the miss map is the run on the platform's shared levels, as the study's: it equals
    simulate_shared_run's per-pixel misses on the study's SharedLevels, and for a static mapping (no task
    counter) its misses summed over the pixels equal the study's run at that count (its processes'
    ``<level>_misses`` summed); the miss-ratio curves have a point at each of the platform's whole levels;
    summary.json names each section's view. Mutations: ``hierarchy=hierarchy`` for the miss map in
    report._assemble (the thread view's map); ``hierarchy`` instead of ``recorded`` for the curves there."""
    from analyses.experiment import Experiment
    from analyses.report import build_report
    from analyses.traces import cached_trace
    from coherence.shared_run import simulate_shared_run
    from coherence.studies import place_layout

    m1 = get_platform("apple-m1")
    experiment = Experiment(scene="tetra", size=8, mappings=("S", "P"), n_processes=(1, 4), platform="apple-m1",
                            cache_dir=tmp_path / "cache", progress=False)
    report = build_report(experiment, miss_map="P:4")
    misses = report.miss_map.misses
    processes = report.processes[(report.processes["mapping"] == "P") & (report.processes["n_processes"] == 4)]
    assert misses.sum(axis=(0, 1)).tolist() == [int(processes[f"{level}_misses"].sum()) for level in ("L1", "L2")]
    assert misses[..., 0].sum() > 0
    scene, trace, _ = cached_trace("tetra", 8, cache_dir=tmp_path / "cache", kd=experiment.kd_builder(),
                                   max_depth=experiment.max_depth, progress=False,
                                   workload=experiment.trace_workload(), tree_variant=experiment.tree_variant,
                                   path_samples=(experiment.spp, experiment.seed))
    shared = experiment.study_hierarchy()
    expected = simulate_shared_run(trace, get_mapping("P").build(8, 8, 4), shared.machine,
                                   place_layout(experiment.layout_object(), trace, scene), m1.cost,
                                   experiment.machine(), interleave_cycles=shared.interleave_cycles,
                                   record=("pixel_misses",)).run.pixel_misses
    np.testing.assert_array_equal(misses, expected)
    whole = {level.size for level in m1.hierarchy.hierarchy.levels}
    for _, curve in report.curves.groupby("order"):
        assert whole <= set(curve["size"])
    views = report.summary["views"]
    assert views["miss_map"]["view"] == "shared run" and views["miss_curves"]["view"] == "no machine"
    assert report.summary["miss_map"]["caches"] == views["miss_map"]["what"]
    assert f"4 processes on {m1.name}" in report.html and "the same on any machine" in report.html
    assert "views" not in build_report(Experiment(scene="tetra", size=8, mappings=("S",), n_processes=(1, 2),
                                                  cache_dir=tmp_path / "cache", progress=False)).summary
