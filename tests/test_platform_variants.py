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
    """A point's cores, smt and l3_size make the platform's variant, whose thread view and hardware threads
    the point simulates; frame_buffer_bytes sets the layout's pixels. Mutation: ``n_cpus = int(point.get(
    "n_cpus", study.n_cpus))`` in configure (the CPUs stay the platform's 32)."""
    zen4 = get_platform("zen4-7950x")
    grid = dict(parse_grid_flag(flag) for flag in ("cores=4,8", "smt=on,off", "l3_size=16MB",
                                                  "frame_buffer_bytes=3,16"))
    study = WhatIf.of("today", grid, scene="tetra", size=8, platform="zen4-7950x")
    point = {"cores": 8, "smt": "off", "l3_size": 16 * _MB, "frame_buffer_bytes": 3}
    hierarchy, layout, cost, machine, n_processes = configure(study, point)
    variant = zen4.variant(cores=8, smt=False, l3_size=16 * _MB)
    assert hierarchy == variant.thread_view() and machine.n_cpus == 8 and cost == zen4.cost
    assert layout.record("frame_buffer").size == 3 and n_processes == 8
    assert configure(study, {"cores": 4, "smt": "on", "l3_size": 16 * _MB, "frame_buffer_bytes": 16})[3].n_cpus == 8


@pytest.mark.parametrize("grid, base, message", [
    ({"cores": [4]}, {}, r"grid\['cores'\] varies a platform: give the base one"),
    ({"smt": ["maybe"]}, {"platform": "zen4-7950x"}, "smt must be on or off or threads per core, got 'maybe'"),
    ({"prefetch": ["on"]}, {"platform": "zen4-7950x"}, "prefetch on: the schedule simulation does not model"),
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
