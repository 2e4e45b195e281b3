"""Validation, presets and TOML/JSON files of cache hierarchies."""
import json

import pytest

from cachesim import CacheLevel, Hierarchy, alpha21164, alpha21164_noninclusive, get_hierarchy, modern


def test_alpha_preset_geometry():
    l1, l2, l3 = alpha21164().levels
    assert (l1.size, l1.line_size, l1.ways, l1.n_sets) == (8192, 32, 1, 256)
    assert (l2.size, l2.line_size, l2.ways, l2.n_sets) == (98304, 64, 3, 512)
    assert (l3.size, l3.line_size, l3.ways, l3.n_sets) == (4 << 20, 64, 1, 65536)


def test_alpha_preset_follows_the_manual():
    # D-cache write-through read-allocate, S-cache and B-cache write-allocate,
    # B-cache a superset of both: inclusive. The variant differs only there.
    hierarchy = alpha21164()
    assert hierarchy.inclusion == "inclusive"
    assert [level.write_allocate for level in hierarchy.levels] == [False, True, True]
    variant = get_hierarchy("alpha21164-noninclusive")
    assert variant == alpha21164_noninclusive()
    assert variant.inclusion == "non-inclusive" and variant.levels == hierarchy.levels


def test_non_power_of_two_set_count_is_allowed():
    level = CacheLevel("L2", 96 * 1024, 64, 2)
    assert level.n_sets == 768


def test_full_associativity():
    level = CacheLevel("L1", 4096, 64, "FULL")
    assert level.assoc == "full" and level.ways == 64 and level.n_sets == 1


@pytest.mark.parametrize("kwargs, field", [
    (dict(size=0), "size"),
    (dict(size=1000), "size"),            # not a whole number of sets
    (dict(line_size=48), "line_size"),
    (dict(line_size=16384), "line_size"),
    (dict(assoc=0), "assoc"),
    (dict(assoc="most"), "assoc"),
    (dict(assoc=2.0), "assoc"),
    (dict(policy="mru"), "policy"),
    (dict(latency=-1), "latency"),
    (dict(latency=float("nan")), "latency"),
    (dict(seed=-3), "seed"),
    (dict(name=""), "name"),
    (dict(write_allocate=1), "write_allocate"),
])
def test_bad_level_names_the_field(kwargs, field):
    arguments = dict(name="L1", size=8192, line_size=32, assoc=1)
    arguments.update(kwargs)
    with pytest.raises(ValueError, match=field):
        CacheLevel(**arguments)


def test_inconsistent_hierarchies_are_rejected():
    small = CacheLevel("L1", 8192, 64, 2)
    with pytest.raises(ValueError, match="line_size may only grow"):
        Hierarchy((small, CacheLevel("L2", 65536, 32, 4)))
    with pytest.raises(ValueError, match="exclusive"):
        Hierarchy((CacheLevel("L1", 8192, 32, 2), CacheLevel("L2", 65536, 64, 4)), inclusion="exclusive")
    with pytest.raises(ValueError, match="distinct names"):
        Hierarchy((small, CacheLevel("L1", 65536, 64, 4)))
    with pytest.raises(ValueError, match="inclusion"):
        Hierarchy((small,), inclusion="mostly")
    with pytest.raises(ValueError, match="levels"):
        Hierarchy(())
    with pytest.raises(ValueError, match="memory_latency"):
        Hierarchy((small,), memory_latency=-5)


@pytest.mark.parametrize("suffix", [".toml", ".json"])
@pytest.mark.parametrize("preset", [alpha21164, alpha21164_noninclusive, modern])
def test_round_trip_through_files(tmp_path, suffix, preset):
    hierarchy = preset()
    path = hierarchy.save(tmp_path / f"h{suffix}")
    assert Hierarchy.load(path) == hierarchy
    assert get_hierarchy(str(path)) == hierarchy
    assert [p.name for p in tmp_path.iterdir()] == [path.name]  # no temporary left behind


def test_bad_files_name_file_and_field(tmp_path):
    path = tmp_path / "h.json"
    data = alpha21164().to_dict()
    data["levels"][1]["assoc"] = 0
    path.write_text(json.dumps(data))
    with pytest.raises(ValueError, match=r"h\.json: levels\[1\].*assoc"):
        Hierarchy.load(path)
    path.write_text('{"levels": [}')
    with pytest.raises(ValueError, match=r"h\.json:1:\d+: not valid JSON"):
        Hierarchy.load(path)
    toml = tmp_path / "h.toml"
    toml.write_text("levels = [ { name = 'L1', size = 8192 } ]")
    with pytest.raises(ValueError, match="missing field.*line_size"):
        Hierarchy.load(toml)
    toml.write_text("levels = [ { name = 'L1', size = 8192, line_size = 32, colour = 'red' } ]")
    with pytest.raises(ValueError, match="unknown field.*colour"):
        Hierarchy.load(toml)
    with pytest.raises(FileNotFoundError):
        Hierarchy.load(tmp_path / "absent.toml")
    with pytest.raises(ValueError, match="unknown hierarchy"):
        get_hierarchy("alpha")
    with pytest.raises(ValueError, match=".toml or .json"):
        alpha21164().save(tmp_path / "h.yaml")


def test_saved_files_get_ordinary_permissions(tmp_path):
    import os
    import stat

    from cachesim import alpha21164

    path = alpha21164().save(tmp_path / "a.toml")
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(path.stat().st_mode) == 0o666 & ~umask
    assert not list(tmp_path.glob("*.tmp"))
