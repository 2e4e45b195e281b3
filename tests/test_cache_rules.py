"""The two rules of docs/cache_rules.md, each on a hand-checked stream that
another simulator's rule would change."""
import pytest

from cachesim import CacheLevel, Hierarchy, simulate

A, B, C = 0, 64, 128  # three 64-byte lines


@pytest.mark.parametrize("assoc", [2, "full"])
def test_inclusive_fills_run_from_the_lowest_level_up(assoc):
    """Fails if ``_fill_levels`` in cachesim/full.py fills top-down
    (``range(last_level, served)``): L1 would evict B for C and the last B would go to L2.

    L1 and L2 hold two lines each. After A, B, A the lines' recency differs:
    L1 saw A's hit, L2 did not. C misses both: L2 evicts A, its least recent,
    and invalidates it in L1, which then takes C into the emptied way and
    keeps B, so the last access hits L1.
    """
    hierarchy = Hierarchy((CacheLevel("L1", 128, 64, assoc), CacheLevel("L2", 128, 64, assoc)),
                          inclusion="inclusive")
    result = simulate([A, B, A, C, B], hierarchy, return_levels=True)
    assert result.served_by.tolist() == [2, 2, 0, 2, 0]
    assert result.evictions.tolist() == [0, 1]
    assert result.invalidations.tolist() == [1, 0]
    assert result.state.resident_lines("L1").tolist() == [B // 64, C // 64]


@pytest.mark.parametrize("l1_assoc", [1, 2])
def test_a_write_goes_down_as_a_write_below_a_write_allocating_level(l1_assoc):
    """Fails if a write fills a level whose ``write_allocate`` is false, as a
    read fetch would (Dinero IV's rule): drop the ``continue`` of
    ``_fill_levels`` in cachesim/full.py (2-way L1) or make the L2 fill of
    cachesim/direct_first.py unconditional (direct-mapped L1). L2 would then
    hold A and serve its last read.

    L1 (128 B, write-allocate) over L2 (256 B 2-way, no write-allocate),
    non-inclusive. The write to A misses both and reaches L2 as a write; only
    L1 takes A. B and C evict A from L1 (A and C share L1's set when
    direct-mapped; two ways fill up otherwise), so the last read of A goes to
    memory: L2 never held it.
    """
    hierarchy = Hierarchy((CacheLevel("L1", 128, 64, l1_assoc, write_allocate=True),
                           CacheLevel("L2", 256, 64, 2, write_allocate=False)))
    write = simulate([A], hierarchy, writes=[True], return_levels=True)
    assert write.write_accesses.tolist() == [1, 1] and write.write_misses.tolist() == [1, 1]
    assert write.read_accesses.tolist() == [0, 0]
    assert write.state.resident_lines("L1").tolist() == [A // 64]
    assert write.state.resident_lines("L2").tolist() == []
    reads = simulate([B, C, A], write.state, return_levels=True)
    assert reads.served_by.tolist() == [2, 2, 2]
