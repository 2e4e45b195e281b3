"""SharedHierarchy: levels shared by hardware threads, validated and saved like a Hierarchy."""
import json

import pytest

from cachesim import alpha21164, modern
from cachesim.sharing import SHARING, SharedHierarchy, get_shared_hierarchy, private


def four_by_two():
    return SharedHierarchy(modern(), n_cores=4, smt=2, cores_per_complex=2,
                           shared_by=("thread", "core", "complex"))


def test_instances_follow_threads_cores_and_complexes():
    """Thread t is on core t // smt, in complex core // cores_per_complex; the counts are derived
    by hand for 4 cores x 2 threads in complexes of 2 cores.
    Mutation: return ``self.smt * self.n_cores`` for "complex" in threads_per_instance."""
    machine = four_by_two()
    assert machine.n_threads == 8
    assert [machine.threads_per_instance(level) for level in range(3)] == [1, 2, 4]
    assert [machine.n_instances(level) for level in range(3)] == [8, 4, 2]
    assert [machine.instance_of(1, thread) for thread in range(8)] == [0, 0, 1, 1, 2, 2, 3, 3]
    assert [machine.instance_of(2, thread) for thread in range(8)] == [0, 0, 0, 0, 1, 1, 1, 1]
    whole = SharedHierarchy(modern(), n_cores=4, smt=2, shared_by=("thread", "thread", "machine"))
    assert whole.cores_per_complex == 4 and whole.n_instances(2) == 1 and whole.n_instances(1) == 8


def test_default_is_private_to_each_thread():
    """Mutation: default shared_by to ("machine",) * n_levels."""
    machine = private(alpha21164(), n_cores=2, smt=2)
    assert machine.shared_by == ("thread",) * 3
    assert [machine.n_instances(level) for level in range(3)] == [4, 4, 4]


@pytest.mark.parametrize("kwargs, field", [
    ({"n_cores": 0}, "n_cores"),
    ({"n_cores": 2.0}, "n_cores"),
    ({"smt": 9}, "smt"),
    ({"n_cores": 6, "cores_per_complex": 4}, "cores_per_complex"),
    ({"cores_per_complex": 3}, "cores_per_complex"),
    ({"shared_by": ("thread", "core")}, "shared_by"),
    ({"shared_by": "machine"}, "shared_by"),
    ({"shared_by": ("thread", "socket", "machine")}, "shared_by of L2"),
    ({"shared_by": ("core", "thread", "machine")}, "shared_by: L2 \\(thread\\) may not be shared less widely than L1"),
])
def test_bad_machines_name_the_field(kwargs, field):
    """Mutation: drop the check of the named field in SharedHierarchy.__post_init__."""
    with pytest.raises(ValueError, match=f"SharedHierarchy.{field}"):
        SharedHierarchy(modern(), **kwargs)
    with pytest.raises(ValueError, match="must be a Hierarchy"):
        SharedHierarchy("modern")


@pytest.mark.parametrize("suffix", [".toml", ".json"])
def test_round_trip_through_files(tmp_path, suffix):
    """Mutation: leave "shared_by" out of to_dict's levels."""
    machine = four_by_two()
    path = machine.save(tmp_path / f"machine{suffix}")
    assert SharedHierarchy.load(path) == machine
    assert get_shared_hierarchy(str(path)) == machine
    assert [p.name for p in tmp_path.iterdir()] == [path.name]


def test_a_hierarchy_file_reads_as_one_thread(tmp_path):
    """A plain hierarchy file (no machine fields, no shared_by) is one core of one thread.
    Mutation: make from_dict require "n_cores"."""
    path = alpha21164().save(tmp_path / "alpha.toml")
    machine = SharedHierarchy.load(path)
    assert machine == private(alpha21164()) and machine.n_threads == 1
    assert get_shared_hierarchy(alpha21164()) == machine


def test_bad_files_name_file_and_field(tmp_path):
    """Mutation: drop the ``f"{source}: "`` prefix in from_dict's re-raise."""
    data = four_by_two().to_dict()
    data["levels"][2]["shared_by"] = "everyone"
    path = tmp_path / "machine.json"
    path.write_text(json.dumps(data))
    with pytest.raises(ValueError, match=r"machine\.json: SharedHierarchy\.shared_by of L3 must be one of "
                                         + ", ".join(SHARING)):
        SharedHierarchy.load(path)
    data = four_by_two().to_dict()
    data["smt"] = 0
    path.write_text(json.dumps(data))
    with pytest.raises(ValueError, match=r"machine\.json: SharedHierarchy\.smt"):
        SharedHierarchy.load(path)
    data["smt"] = 2
    data["levels"][0]["colour"] = "red"
    path.write_text(json.dumps(data))
    with pytest.raises(ValueError, match=r"machine\.json: levels\[0\]: unknown field.*colour"):
        SharedHierarchy.load(path)
    with pytest.raises(ValueError, match="unknown shared hierarchy"):
        get_shared_hierarchy("zen4")
    with pytest.raises(ValueError, match=".toml or .json"):
        four_by_two().save(tmp_path / "machine.yaml")
