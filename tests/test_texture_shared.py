"""The report's texture section under a platform: texel reads and misses from runs on its shared levels."""
import numpy as np
import pytest

from cachesim import CacheLevel, Hierarchy
from cachesim.sets import ACCESSES, MISSES
from cachesim.sharing import SharedHierarchy
from coherence.cost import get_cost_model
from coherence.layout import get_layout
from coherence.mappings import get_mapping
from coherence.shared_run import SharedLevels, simulate_shared_run
from coherence.simulation import Machine
from coherence.studies import place_layout
from tracer.trace.access import COUNTER_NAMES, AccessTrace, RecordKind, pack

COST = get_cost_model("modern")


def two_texel_trace():
    """Two pixels; each reads sphere 0, then texels 0 and 1 of one 2x1 texture."""
    kinds = np.array([RecordKind.SPHERE, RecordKind.TEXEL, RecordKind.TEXEL])
    records = [pack(kinds, np.array([0, 0, 1]), np.zeros(3, dtype=bool)) for _ in range(2)]
    counters = np.zeros((2, len(COUNTER_NAMES)), dtype=np.int64)
    return AccessTrace(np.array([0, 3, 6], dtype=np.int64), np.concatenate(records), counters, 2, 1,
                       {"textures": [[[2, 1]]]})


def test_two_threads_share_the_texels_second_reader_hits_the_shared_l2():
    """Two cores with private L1s and one shared L2 run P's two processes, one pixel each. Both texels lie on
    one line, the sphere on another. Whatever the interleaving, each thread's L1 misses the texel line once
    and hits it once (L1: 4 texel reads, 2 misses), and only the first thread to reach the shared L2 misses
    there (L2: 2 texel reads, 1 miss); each level's misses are the texel line's and the sphere line's (L1 4,
    L2 2), so texels make half of them. A thread's private copy of the levels would miss twice at L2.
    Mutations: ``shared.counts.sum(axis=1)`` -> ``shared.counts[:, 0]`` in shared_misses_by_kind (one
    instance only: L1 reads 2); ``shared=shared`` -> ``shared=None`` in the call below (each process's
    private hierarchy: L2 texel misses 2)."""
    from analyses.report_texture import texture_section

    trace = two_texel_trace()
    layout = get_layout("compact")
    placed = place_layout(layout, trace)
    texel = placed.kind_first[RecordKind.TEXEL]
    sphere = placed.kind_first[RecordKind.SPHERE]
    assert placed.record_start[texel] // 32 == placed.record_start[texel + 1] // 32  # one line holds both texels
    assert placed.record_start[texel] // 32 != placed.record_start[sphere] // 32
    hierarchy = Hierarchy((CacheLevel("L1", 1024, 32, 2, "lru", latency=1),
                           CacheLevel("L2", 8192, 32, 4, "lru", latency=6)), memory_latency=40, name="two")
    shared = SharedLevels(SharedHierarchy(hierarchy, n_cores=2, smt=1, shared_by=("thread", "machine")), 1)
    section = texture_section(trace, None, layout, hierarchy, [get_mapping("P")], 2, COST, shared=shared,
                              machine=Machine(n_cpus=2, quantum_cycles=0))
    share = section["share"].set_index("level")
    assert share["texel_reads"].tolist() == [4, 2]
    assert share["texel_misses"].tolist() == [2, 1]
    assert share["texture_miss_share"].tolist() == [0.5, 0.5]
    linear = section["layouts"][section["layouts"]["layout"] == "linear"].set_index("level")
    assert linear["texel_hit_rate"].tolist() == [0.5, 0.5]


def test_report_share_table_under_a_platform_is_the_shared_runs_texel_counts(tmp_path):
    """Under a platform, the report's ``texture`` rows at the verdict's process count are, per mapping and
    level, the texel accesses and misses of simulate_shared_run on the study's shared levels and machine,
    summed over the level's instances by hand here, and the texels' share of the level's misses, those being
    the processes' own (in a run without background load they equal every kind's misses summed over the
    instances); summary.json says the section is a shared run and keeps no thread view. Mutations: drop
    ``shared=...`` in report._assemble's texture_section call (the thread view's counts);
    ``processes[f"{level}_misses"]`` -> ``processes[f"{level}_hits"]`` in shared_texel_table. Its texel
    miss-ratio curves reach four times the platform's whole largest level, as the report's other curves do
    (mutation: ``reach = hierarchy`` in texture_section, the thread view under a platform)."""
    from analyses.experiment import Experiment
    from analyses.report import build_report
    from analyses.traces import cached_trace

    experiment = Experiment(scene="balls-textured", size=8, mappings=("S", "DB"), n_processes=(1, 2),
                            platform="apple-m1", cache_dir=tmp_path / "cache", progress=False)
    report = build_report(experiment)
    assert report.summary["views"]["texture"]["view"] == "shared run" and "thread_view" not in report.summary
    assert "cold hierarchy" not in report.summary["results_csv"]["sections"]["texture"]
    scene, trace, _ = cached_trace("balls-textured", 8, cache_dir=tmp_path / "cache", kd=experiment.kd_builder(),
                                   max_depth=experiment.max_depth, progress=False,
                                   workload=experiment.trace_workload(), tree_variant=experiment.tree_variant,
                                   path_samples=(experiment.spp, experiment.seed))
    shared = experiment.study_hierarchy()
    placed = place_layout(experiment.layout_object(), trace, scene)
    names = shared.hierarchy.level_names
    rows = report.results[report.results["section"] == "texture"]
    assert set(rows["mapping"]) == {"S", "DB"} and set(rows["n_processes"]) == {2}
    curve_sizes = report.results.loc[report.results["section"] == "texture_miss_ratio", "item"].astype(int)
    whole = max(level.size for level in experiment.recorded_hierarchy().levels)
    assert whole > max(level.size for level in experiment.hierarchy_object().levels)
    assert curve_sizes.max() <= 4 * whole < 2 * curve_sizes.max()  # sizes double from the line size

    def run_of(mapping, machine):
        return simulate_shared_run(trace, get_mapping(mapping).build(8, 8, 2), shared.machine, placed,
                                   experiment.cost_model(), machine, interleave_cycles=shared.interleave_cycles)

    quiet = run_of("DB", Machine(n_cpus=shared.machine.n_threads))
    assert [int(quiet.run.processes[f"{name}_misses"].sum()) for name in names] == \
        [int(quiet.shared.counts[level, :, :, MISSES].sum()) for level in range(len(names))]
    for mapping in ("S", "DB"):
        run = run_of(mapping, experiment.machine())
        counts = run.shared.counts
        mine = rows[rows["mapping"] == mapping]
        for level, name in enumerate(names):
            reads = sum(int(counts[level, i, RecordKind.TEXEL, ACCESSES]) for i in range(counts.shape[1]))
            misses = sum(int(counts[level, i, RecordKind.TEXEL, MISSES]) for i in range(counts.shape[1]))
            at = mine[mine["item"] == name].set_index("metric")["value"]
            assert reads > 0, (mapping, name)
            assert int(at["texel_reads"]) == reads and int(at["texel_misses"]) == misses
            every = int(run.run.processes[f"{name}_misses"].sum())
            assert np.isclose(float(at["texture_miss_share"]), misses / every, rtol=1e-5)


def test_whatif_texture_columns_under_a_platform_are_the_points_shared_runs_counts(tmp_path):
    """A textured what-if under apple-m1 (balls-textured 8x8, S and DB at 2 processes beside one background
    process, texel orders linear and morton): per row and level, ``texel_<level>_misses_per_access`` is the
    texel misses over the texel reads of simulate_shared_run on the platform's shared levels and machine with
    the point's texel order, summed over the level's instances by hand here, and ``texture_<level>_miss_share``
    those misses over the processes' own misses (the background's reads, kind 0, left out). Mutations:
    ``shared_texture_columns(result, mapping, n_processes)`` -> ``_texture_columns(trace, scene, mapping,
    n_processes, caches.hierarchy, layout, cost)`` in evaluate_point (each process's private copy of the
    levels); drop the second argument of texture_summary in shared_texture_columns (the background's misses
    counted in the share); drop ``& (kinds["n_processes"] == n_processes)`` there (the 1-process runs added)."""
    from analyses.traces import cached_trace
    from analyses.whatif import WhatIf, run_whatif
    from coherence.texture_layout import TextureLayout

    study = WhatIf.of("texture", {"texture_layout": ["linear", "morton"]}, scene="balls-textured", size=8,
                      mappings=("S", "DB"), n_processes=(2,), platform="apple-m1", background=1)
    table = run_whatif(study, n_jobs=1, cache_dir=tmp_path / "cache", progress=False)
    assert sorted(zip(table["texture_layout"], table["mapping"])) == [
        ("linear", "DB"), ("linear", "S"), ("morton", "DB"), ("morton", "S")]
    experiment = study.experiment
    scene, trace, _ = cached_trace("balls-textured", 8, cache_dir=tmp_path / "cache", kd=experiment.kd,
                                   max_depth=experiment.max_depth, progress=False,
                                   workload=experiment.trace_workload(), tree_variant=experiment.tree_variant)
    shared = experiment.study_hierarchy()
    machine = experiment.machine()
    assert machine.n_cpus == shared.machine.n_threads and machine.background_load == 1
    names = shared.hierarchy.level_names
    background_seen = False
    for row in table.itertuples(index=False):
        layout = experiment.layout_object().with_texels(TextureLayout.from_label(row.texture_layout))
        run = simulate_shared_run(trace, get_mapping(row.mapping).build(8, 8, 2), shared.machine,
                                  place_layout(layout, trace, scene), experiment.cost_model(), machine,
                                  interleave_cycles=shared.interleave_cycles)
        counts = run.shared.counts
        for level, name in enumerate(names):
            reads = sum(int(counts[level, i, RecordKind.TEXEL, ACCESSES]) for i in range(counts.shape[1]))
            misses = sum(int(counts[level, i, RecordKind.TEXEL, MISSES]) for i in range(counts.shape[1]))
            own = int(run.run.processes[f"{name}_misses"].sum())
            background_seen |= own != int(counts[level, :, :, MISSES].sum())
            assert reads > 0 and own > 0, (row.mapping, name)
            assert getattr(row, f"texel_{name}_misses_per_access") == pytest.approx(misses / reads, rel=1e-12)
            assert getattr(row, f"texture_{name}_miss_share") == pytest.approx(misses / own, rel=1e-12)
    assert background_seen  # the share's denominator leaves out misses that happened
