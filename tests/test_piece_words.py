"""coherence.piece_words: one word per access of a run on shared levels."""
import numpy as np
import pytest

from coherence.piece_words import MAX_PIECE_BYTES, pack_pieces


def fields(rng, n):
    return (rng.integers(0, np.iinfo(np.uint64).max, n, dtype=np.uint64, endpoint=True),
            rng.integers(1, MAX_PIECE_BYTES + 1, n), rng.integers(0, 16, n).astype(np.uint8), rng.random(n) < 0.3,
            rng.random(n) < 0.5)


@pytest.mark.parametrize("seed", range(5))
def test_every_field_comes_back_unchanged(seed):
    """Seeded random fields over their whole ranges (any 64-bit address, 1 ... 1024 bytes, kinds 0-15) read
    back as given. Mutation: ``KIND_SHIFT = np.uint16(SIZE_BITS)`` -> ``SIZE_BITS - 1`` (the kind overlaps the
    size)."""
    rng = np.random.default_rng(seed)
    n = 1000
    addresses, sizes, kinds, writes, private = fields(rng, n)
    addresses[:2] = [0, np.iinfo(np.uint64).max]
    sizes[:2] = [1, MAX_PIECE_BYTES]
    pieces = pack_pieces([0, 400, 400, n], addresses, sizes, kinds, writes, private, 8192)
    assert pieces.words.dtype == np.uint16 and pieces.private_span == 8192
    np.testing.assert_array_equal(pieces.addresses, addresses)
    np.testing.assert_array_equal(pieces.sizes, sizes)
    np.testing.assert_array_equal(pieces.kinds, kinds)
    np.testing.assert_array_equal(pieces.writes, writes)
    np.testing.assert_array_equal(pieces.private, private)
    np.testing.assert_array_equal(pieces.piece_offsets, [0, 400, 400, n])


def test_a_word_worked_by_hand():
    """3 bytes of kind 9, a write to a private copy: (3 - 1) | 9 << 10 | 1 << 14 | 1 << 15; a read of 64 bytes
    of kind 0: 63. The addresses stay as given."""
    pieces = pack_pieces([0, 2], [0x1234, 1 << 50], [3, 64], [9, 0], [True, False], [True, False], 4096)
    assert pieces.words.tolist() == [2 | 9 << 10 | 1 << 14 | 1 << 15, 63]
    assert pieces.addresses.tolist() == [0x1234, 1 << 50]


@pytest.mark.parametrize("change, message", [
    (dict(sizes=[0]), "1 ... 1024"),
    (dict(sizes=[MAX_PIECE_BYTES + 1]), "1 ... 1024"),
    (dict(kinds=[16]), "not below 16"),
    (dict(piece_offsets=[0, 2]), "rise from 0 to the 1 accesses"),
    (dict(writes=[True, False]), "must all have shape"),
])
def test_fields_out_of_range_are_refused_by_name(change, message):
    given = dict(piece_offsets=[0, 1], addresses=[64], sizes=[4], kinds=[1], writes=[False], private=[False],
                 private_span=4096)
    given.update(change)
    with pytest.raises(ValueError, match=message):
        pack_pieces(**given)
