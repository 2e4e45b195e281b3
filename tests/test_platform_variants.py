"""Platform variants (cores, SMT, shared-L3 size, prefetchers) and the what-if grid keys that vary them."""
import pytest

from analyses.whatif import WhatIf, configure, parse_grid_flag
from coherence.platforms import PREFETCHERS_ON, get_platform

_MB = 1024 * 1024


def test_fewer_cores_without_smt_give_each_thread_a_larger_share():
    """zen4-7950x with 8 cores and SMT off: one complex of 8 threads, so a thread's L3 share is 32 MB / 8 =
    4 MB and its L2 the whole 1 MB (hand-checked). Mutation: drop ``per_complex = min(per_complex, n_cores)``
    (then 4 cores cannot fill a complex of 8 and are refused)."""
    zen4 = get_platform("zen4-7950x")
    eight = zen4.variant(cores=8, smt=False)
    assert (eight.hierarchy.n_cores, eight.hierarchy.smt, eight.n_threads) == (8, 1, 8)
    assert [level.size for level in eight.thread_view().levels] == [32 * 1024, _MB, 4 * _MB]
    assert eight.name == "zen4-7950x[cores=8,smt=1]" and eight.cost == zen4.cost
    four = zen4.variant(cores=4)
    assert four.hierarchy.cores_per_complex == 4 and four.n_threads == 8
    assert four.thread_view().levels[2].size == 32 * _MB // 8


def test_l3_size_is_the_whole_shared_level_and_prefetch_sets_the_documented_prefetchers():
    """A 16 MB L3 per complex of 8 SMT2 cores is 1 MB a thread (hand-checked); prefetch on puts
    PREFETCHERS_ON on L1 and L2 and nothing on L3. Mutation: ``size=l3_size // 2`` in variant."""
    zen4 = get_platform("zen4-7950x")
    smaller = zen4.variant(l3_size=16 * _MB, prefetch=True)
    assert smaller.hierarchy.hierarchy.levels[2].size == 16 * _MB
    assert smaller.thread_view().levels[2].size == _MB
    assert [level.prefetcher for level in smaller.hierarchy.hierarchy.levels] == [*PREFETCHERS_ON, None]
    assert smaller.name == f"zen4-7950x[l3={16 * _MB},prefetch]"


def test_a_variant_that_changes_nothing_is_the_platform():
    """Mutation: ``if threads != machine.smt or True:`` (smt=on would rename the platform)."""
    m1 = get_platform("apple-m1")
    assert m1.variant(cores=4, smt=True, prefetch=False) is m1
    assert get_platform("xeon-8480").variant(smt=True).name == "xeon-8480"


@pytest.mark.parametrize("choice, message", [
    ({"cores": 12}, "cores must fill whole core complexes of 8 on zen4-7950x, got 12"),
    ({"cores": 0}, r"cores must be in \[1, 1024\], got 0"),
    ({"smt": 9}, r"smt must be in \[1, 8\], got 9"),
    ({"l3_size": 1000}, r"l3_size: CacheLevel\('L3'\).size \(1000\) must be a multiple"),
    ({"prefetch": "yes"}, "prefetch must be True or False"),
])
def test_bad_variants_are_refused_by_name(choice, message):
    """Mutation: drop the ``n_cores % per_complex`` check in variant (12 cores pass)."""
    with pytest.raises(ValueError, match=f"Platform.variant: {message}"):
        get_platform("zen4-7950x").variant(**choice)
    with pytest.raises(ValueError, match="apple-m1 has no L3"):
        get_platform("apple-m1").variant(l3_size=_MB)


def test_whatif_grid_varies_the_platform_and_the_pixel_size():
    """A point's cores, smt and l3_size make the platform's variant, whose shared levels and hardware threads
    the point simulates; frame_buffer_bytes sets the layout's pixels. Mutation: ``n_cpus = int(point.get(
    "n_cpus", study.n_cpus))`` in configure (the CPUs stay the platform's 32)."""
    zen4 = get_platform("zen4-7950x")
    grid = dict(parse_grid_flag(flag) for flag in ("cores=4,8", "smt=on,off", "l3_size=16MB",
                                                  "frame_buffer_bytes=3,16"))
    study = WhatIf.of("today", grid, scene="tetra", size=8, platform="zen4-7950x")
    point = {"cores": 8, "smt": "off", "l3_size": 16 * _MB, "frame_buffer_bytes": 3}
    hierarchy, layout, cost, machine, n_processes = configure(study, point)
    variant = zen4.variant(cores=8, smt=False, l3_size=16 * _MB)
    assert hierarchy.machine == variant.hierarchy and machine.n_cpus == 8 and cost == zen4.cost
    assert layout.record("frame_buffer").size == 3 and n_processes == 8
    assert configure(study, {"cores": 4, "smt": "on", "l3_size": 16 * _MB, "frame_buffer_bytes": 16})[3].n_cpus == 8


@pytest.mark.parametrize("grid, base, message", [
    ({"cores": [4]}, {}, r"grid\['cores'\] varies a platform: give the base one"),
    ({"smt": ["maybe"]}, {"platform": "zen4-7950x"}, "smt must be on or off or threads per core, got 'maybe'"),
    ({"prefetch": ["sometimes"]}, {"platform": "zen4-7950x"}, "prefetch must be on or off, got 'sometimes'"),
    ({"frame_buffer_bytes": [5]}, {}, "frame-buffer pixel size must be one of 3, 4, 16"),
    ({"l3_size": ["1MB"]}, {"platform": "apple-m1"}, "apple-m1 has no L3"),
])
def test_bad_grid_points_are_refused_before_any_run(grid, base, message):
    """Mutation: drop the PLATFORM_VARIANTS check in WhatIf.__post_init__ (cores without a platform pass)."""
    with pytest.raises(ValueError, match=message):
        WhatIf.of("bad", grid, scene="tetra", size=8, **base)


def test_whatif_help_names_every_platform_key(capsys):
    """Mutation: drop the line naming the variants from the whatif epilog."""
    from analyses.cli import main

    with pytest.raises(SystemExit):
        main(["whatif", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    for key in ("frame_buffer_bytes (3, 4, 16)", "cores (", "smt (on, off", "l3_size (", "prefetch (on, off"):
        assert key in text


def test_whatif_cli_varies_a_platform(tmp_path, capsys):
    """``coherence whatif --platform apple-m1 --grid cores=2,4``: one row per point and mapping, on the shared
    levels (their coherence columns in the CSV). Mutation: ``WhatIf(name="grid", grid=dict(pairs))`` in
    build_study (the grid is checked before the platform is given, and refused)."""
    import pandas as pd

    from analyses.cli import main

    argv = ["whatif", "--platform", "apple-m1", "--grid", "cores=2,4", "--grid", "frame_buffer_bytes=3",
            "--scene", "tetra", "--size", "8", "--mappings", "S", "P", "--processes", "4", "--jobs", "1",
            "--cache", str(tmp_path / "cache"), "--out", str(tmp_path / "out")]
    assert main(argv) == 0, capsys.readouterr().err
    table = pd.read_csv(tmp_path / "out" / "whatif-grid.csv")
    assert sorted(set(zip(table["cores"], table["mapping"]))) == [(2, "P"), (2, "S"), (4, "P"), (4, "S")]
    assert "L1_false_sharing_misses" in set(table["metric"])


def test_whatif_prefetch_on_and_off_run_on_the_shared_levels(tmp_path, capsys):
    """``coherence whatif --platform apple-m1 --grid prefetch=on,off``: the "on" point's prefetch columns are
    those of simulate_shared_run on the variant's shared levels (issued > 0, issued >= useful + useless), the
    "off" point's are 0, and its hit rates are the base platform's run. Mutations: ``if prefetchers is not None:``
    -> ``if False:`` before the access loop's prefetching_access in coherence/shared_schedule.py (no prefetch
    issued); drop ``table[prefetched] = ...fillna(0)`` in run_whatif (the off point's columns are empty); ``timing
    = []`` in evaluate_point (no user_seconds_max)."""
    import numpy as np
    import pandas as pd

    from analyses.cli import main
    from coherence.layout import get_layout
    from coherence.mappings import get_mapping
    from coherence.shared_run import simulate_shared_run
    from coherence.simulation import Machine
    from coherence.studies import place_layout
    from tracer.scenes.catalog import load

    argv = ["whatif", "--platform", "apple-m1", "--grid", "prefetch=on,off", "--scene", "tetra", "--size", "8",
            "--mappings", "P", "--processes", "4", "--jobs", "1",
            "--cache", str(tmp_path / "cache"), "--out", str(tmp_path / "out")]
    assert main(argv) == 0, capsys.readouterr().err
    long = pd.read_csv(tmp_path / "out" / "whatif-grid.csv")
    table = long.pivot_table(index="prefetch", columns="metric", values="value", aggfunc="first")
    from analyses.traces import cached_trace
    from analyses.experiment import Experiment

    experiment = Experiment(scene="tetra", size=8, platform="apple-m1")
    scene, trace, _ = cached_trace("tetra", 8, cache_dir=tmp_path / "cache", workload=experiment.trace_workload(),
                                   progress=False)
    placed = place_layout(get_layout(experiment.layout), trace, scene)
    m1 = get_platform("apple-m1")
    for switch in ("on", "off"):
        machine = m1.variant(prefetch=switch == "on").hierarchy
        run = simulate_shared_run(trace, get_mapping("P").build(8, 8, 4), machine, placed, m1.cost,
                                  Machine(n_cpus=4, background_load=0), interleave_cycles=experiment.interleave_cycles)
        row = table.loc[switch]
        for level, name in enumerate(("L1", "L2")):
            issued, useful, useless = (row[f"{name}_prefetches_{what}"] for what in ("issued", "useful", "useless"))
            if switch == "on":
                assert (issued, useful, useless) == tuple(run.shared.prefetch_counts[level].sum(axis=0))
                assert issued >= useful + useless and issued > 0
            else:
                assert issued == useful == useless == 0
            processes = run.run.processes
            assert row["user_seconds_max"] == pytest.approx(processes["user_seconds"].max())
            assert row[f"{name}_hit_rate"] == pytest.approx(
                processes[f"{name}_hits"].sum() / processes[f"{name}_accesses"].sum())
    assert np.isfinite(table.loc["on", "L1_hit_rate"])


def test_report_under_a_prefetching_variant_counts_prefetches_and_names_each_sections_view(tmp_path):
    """A report on apple-m1 with prefetch on: summary.json's shared_levels carry each level's prefetches issued,
    useful and useless (those of the run's row, issued > 0 at L1); summary.json's views say the miss map is the
    shared run with the prefetchers on and the curves take no machine, marked at the platform's whole levels
    (tetra has no texture section, so nothing takes the thread view); the page's caches are the platform's.
    Mutations: drop ``+ PREFETCH_RUN_COLUMNS`` in shared_levels_summary; ``views = None`` in
    report_tables.summary."""
    from analyses.experiment import Experiment
    from analyses.report import build_report

    m1 = get_platform("apple-m1").variant(prefetch=True)
    experiment = Experiment(scene="tetra", size=8, mappings=("S", "P"), n_processes=(1, 4), platform=m1,
                            cache_dir=tmp_path / "cache", progress=False)
    report = build_report(experiment)
    row = report.runs[(report.runs["n_processes"] == 4) & (report.runs["mapping"] == "P")].iloc[0]
    shared = report.summary["shared_levels"]["4"]["P"]
    for name in ("L1", "L2"):
        for what in ("issued", "useful", "useless"):
            assert shared[name][f"prefetches_{what}"] == row[f"{name}_prefetches_{what}"]
    assert shared["L1"]["prefetches_issued"] > 0
    views = report.summary["views"]
    assert set(views) == {"miss_map", "miss_curves"} and "thread_view" not in report.summary
    assert views["miss_map"]["view"] == "shared run" and "prefetchers on" in views["miss_map"]["what"]
    assert report.summary["miss_map"]["caches"] == views["miss_map"]["what"]
    assert views["miss_curves"]["view"] == "no machine" and "L2 12 MB" in views["miss_curves"]["what"]
    assert "the same on any machine" in report.html
    assert f"{m1.name} caches" in report.html
