"""Work distributions: coverage, hand-checked tiny cases, Block balance, pictures."""
import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from coherence.curves import hilbert_order, morton_order, serpentine_order  # noqa: E402
from coherence.mappings import (  # noqa: E402
    DEFAULT_DISPATCH_CYCLES,
    MAPPINGS,
    Block,
    CurveSegments,
    CurveTiles,
    CustomMapping,
    Distribution,
    DynamicBlock,
    Mapping,
    Pixel,
    Row,
    Strip,
    from_owner_image,
    get_mapping,
)

# Built-ins plus small-parameter variants, so fields, blocks and tiles of
# several sizes (and partial edge ones) appear on small images.
VARIANTS = list(MAPPINGS.values()) + [
    Block(field=5),
    Block(field=1),
    DynamicBlock(block=3, dispatch_cycles=0, take_ahead=2),
    CurveTiles(tile=3, inner="scan"),
    CurveTiles(tile=4, dynamic=True),
    CurveSegments("scan"),
]


def check_distribution(d: Distribution, width: int, height: int, n: int) -> None:
    """Independent checks of the invariants every distribution must meet."""
    assert (d.width, d.height, d.n_processes) == (width, height, n)
    for arr in (d.task_offsets, d.task_pixels):
        assert arr.dtype == np.int64 and arr.flags.c_contiguous and not arr.flags.writeable
    assert d.task_offsets[0] == 0 and d.task_offsets[-1] == width * height
    assert np.all(np.diff(d.task_offsets) >= 0)
    np.testing.assert_array_equal(np.sort(d.task_pixels), np.arange(width * height))
    owner = d.owner_image()
    assert owner.shape == (height, width)
    if d.dynamic:
        assert d.task_process is None
        np.testing.assert_array_equal(np.unique(owner), np.flatnonzero(d.task_lengths))
        return
    assert d.task_process.shape == (d.n_tasks,)
    assert d.task_process.min() >= 0 and d.task_process.max() < n
    streams = [d.process_pixels(p) for p in range(n)]
    np.testing.assert_array_equal(np.sort(np.concatenate(streams)), np.arange(width * height))
    for p, stream in enumerate(streams):
        assert np.all(owner.ravel()[stream] == p)
        expected = np.concatenate([d.task(t) for t in d.process_tasks(p)] + [np.empty(0, np.int64)])
        np.testing.assert_array_equal(stream, expected)
    np.testing.assert_array_equal(d.process_pixel_counts(), [s.size for s in streams])


# ---------------------------------------------------------------- coverage


@settings(max_examples=40, deadline=None)
@given(
    width=st.integers(1, 40),
    height=st.integers(1, 40),
    n=st.one_of(st.integers(1, 17), st.sampled_from([31, 37, 61, 64, 97])),
)
def test_every_mapping_covers_every_pixel_once(width, height, n):
    for mapping in VARIANTS:
        check_distribution(mapping.build(width, height, n), width, height, n)


@pytest.mark.jit_only  # 512x512 for every mapping; smaller sizes run everywhere
@pytest.mark.parametrize("n", [1, 3, 8, 13, 16, 61, 64])
def test_study_size_builds_for_every_mapping(n):
    for mapping in MAPPINGS.values():
        d = mapping.build(512, 512, n)
        np.testing.assert_array_equal(np.bincount(d.task_pixels, minlength=512 * 512), 1)
        if not d.dynamic:
            counts = d.process_pixel_counts()
            assert counts.sum() == 512 * 512


def test_one_process_strip_pixel_row_give_the_same_stream():
    for width, height in [(4, 4), (7, 5), (512, 512)]:
        streams = [m.build(width, height, 1).process_pixels(0) for m in (Strip(), Pixel(), Row())]
        for s in streams:
            np.testing.assert_array_equal(s, np.arange(width * height))


def test_names_and_registry():
    assert list(MAPPINGS) == ["S", "P", "R", "B", "DB", "hilbert", "morton", "serpentine", "hilbert-tiles"]
    for name, mapping in MAPPINGS.items():
        assert mapping.name == name
        assert mapping.build(8, 8, 2).name == name
        assert get_mapping(name) is mapping
    assert get_mapping("db") is MAPPINGS["DB"]
    custom = Block(field=8)
    assert get_mapping(custom) is custom
    with pytest.raises(ValueError, match="unknown mapping 'Q'.*S, P, R, B, DB"):
        get_mapping("Q")
    with pytest.raises(ValueError, match="unknown mapping 3"):
        get_mapping(3)
    assert CurveTiles(inner="scan", dynamic=True).name == "hilbert-tiles-scan-dynamic"


# ---------------------------------------------------------------- hand-checked tiny cases


def owner(mapping: Mapping, width: int, height: int, n: int) -> list:
    return mapping.build(width, height, n).owner_image().tolist()


def test_strip_tiny():
    assert owner(Strip(), 4, 4, 2) == [[0] * 4, [0] * 4, [1] * 4, [1] * 4]
    # 5 rows among 2: the first process gets the extra row
    assert [row[0] for row in owner(Strip(), 3, 5, 2)] == [0, 0, 0, 1, 1]
    # more processes than rows: the last ones get nothing
    d = Strip().build(2, 2, 3)
    np.testing.assert_array_equal(d.task_lengths, [2, 2, 0])
    assert d.process_pixels(2).size == 0


def test_pixel_tiny():
    assert owner(Pixel(), 4, 4, 2) == [[0, 1, 0, 1]] * 4
    d = Pixel().build(4, 4, 2)
    np.testing.assert_array_equal(d.process_pixels(1), np.arange(1, 16, 2))
    assert owner(Pixel(), 3, 2, 2) == [[0, 1, 0], [1, 0, 1]]


def test_row_tiny():
    assert owner(Row(), 4, 4, 2) == [[0] * 4, [1] * 4, [0] * 4, [1] * 4]
    np.testing.assert_array_equal(Row().build(4, 4, 2).process_pixels(1), [4, 5, 6, 7, 12, 13, 14, 15])


def test_block_tiny():
    # n = 2 cuts a field into top and bottom halves (a 2:1 band or column is
    # equally square; ties go to fewer columns)
    assert owner(Block(field=4), 4, 4, 2) == [[0] * 4, [0] * 4, [1] * 4, [1] * 4]
    # n = 4: quadrants, blocks numbered top to bottom, columns left to right
    assert owner(Block(field=4), 4, 4, 4) == [[0, 0, 2, 2], [0, 0, 2, 2], [1, 1, 3, 3], [1, 1, 3, 3]]
    # fields of 2: every 2x2 field repeats the pattern
    d = Block(field=2).build(4, 4, 4)
    assert d.owner_image().tolist() == [[0, 2, 0, 2], [1, 3, 1, 3], [0, 2, 0, 2], [1, 3, 1, 3]]
    # tasks: one per (field, block) in field order, scan order inside
    assert d.n_tasks == 16
    np.testing.assert_array_equal(d.task_process, np.tile(np.arange(4), 4))
    assert [d.task(t).tolist() for t in range(4)] == [[0], [4], [1], [5]]
    assert d.task(4).tolist() == [2]
    # 3x3 in 3: one column of three bands or columns 2+1 are both 3:1 at
    # worst; the tie goes to fewer columns
    assert owner(Block(field=3), 3, 3, 3) == [[0] * 3, [1] * 3, [2] * 3]
    # 4x3 in 2: left and right halves are squarer (2x3) than bands (4x1.5)
    assert owner(Block(field=4), 4, 3, 2) == [[0, 0, 1, 1]] * 3
    # 15 pixels in 2 = 8 + 7: bands cut by pixel count, a partial row between
    d = Block(field=5).build(3, 5, 2)
    assert d.owner_image().tolist() == [[0, 0, 0], [0, 0, 0], [0, 0, 1], [1, 1, 1], [1, 1, 1]]
    np.testing.assert_array_equal(d.task(1), np.arange(8, 15))
    # ... or columns cut in column-major order, a partial column between
    assert owner(Block(field=5), 5, 3, 2) == [[0, 0, 0, 1, 1], [0, 0, 0, 1, 1], [0, 0, 1, 1, 1]]


def _bounding_box(mask: np.ndarray) -> tuple[int, int]:
    ys, xs = np.nonzero(mask)
    return int(np.ptp(xs)) + 1, int(np.ptp(ys)) + 1


@pytest.mark.parametrize("n", range(1, 65))
def test_block_counts_almost_equal_and_blocks_near_square(n):
    d = Block().build(64, 64, n)
    counts = d.process_pixel_counts()
    # the guarantee: within a field, block pixel counts differ by at most one
    # pixel, far inside "one block row's worth"
    assert counts.max() - counts.min() <= 1
    image = d.owner_image()
    for j in range(n):
        mask = image == j
        bw, bh = _bounding_box(mask)
        assert counts.max() - counts.min() <= bw  # one row of the block
        # a rectangle up to one partial row at top and bottom and one partial
        # column at either side
        assert bw * bh - counts[j] <= 2 * (bw - 1) + 2 * (bh - 1)
        # as square as the count allows: primes like 3 end up with 3:1 at worst
        assert max(bw / bh, bh / bw) <= 3.01, (j, bw, bh)


@pytest.mark.parametrize("n", [2, 3, 5, 7, 8, 13, 61, 64])
def test_block_whole_image_per_process_counts_differ_by_at_most_one(n):
    # the extra pixels of each field continue round-robin, so the imbalance
    # does not add up over the 64 fields (nor over edge fields)
    for width, height in [(512, 512), (300, 200)]:
        counts = Block().build(width, height, n).process_pixel_counts()
        assert counts.max() - counts.min() <= 1


def test_block_square_counts_are_exact_squares():
    for n, side in [(4, 32), (16, 16), (64, 8)]:
        image = Block().build(64, 64, n).owner_image()
        for j in range(n):
            assert _bounding_box(image == j) == (side, side)


def test_dynamic_block_tiny():
    d = DynamicBlock(block=2).build(4, 4, 3)
    assert d.dynamic and d.task_process is None
    assert d.n_tasks == 4
    assert [d.task(t).tolist() for t in range(4)] == [[0, 1, 4, 5], [2, 3, 6, 7], [8, 9, 12, 13], [10, 11, 14, 15]]
    assert d.dispatch_cycles == DEFAULT_DISPATCH_CYCLES == 6000.0
    assert d.take_ahead == 0
    assert d.owner_image().tolist() == [[0, 0, 1, 1], [0, 0, 1, 1], [2, 2, 3, 3], [2, 2, 3, 3]]
    with pytest.raises(ValueError, match="static distributions only"):
        d.process_pixels(0)
    # edge blocks are smaller; the study's 512x512 has 256 blocks of 32x32
    d = DynamicBlock(block=2, dispatch_cycles=10, take_ahead=1).build(3, 3, 2)
    assert d.task_lengths.tolist() == [4, 2, 2, 1]
    assert (d.dispatch_cycles, d.take_ahead) == (10.0, 1)
    assert DynamicBlock().build(512, 512, 8).task_lengths.tolist() == [1024] * 256


def test_curve_segments_tiny():
    d = CurveSegments("hilbert").build(4, 4, 2)
    assert d.owner_image().tolist() == [[0, 0, 1, 1]] * 4
    np.testing.assert_array_equal(d.task_pixels, hilbert_order(4, 4))
    d = CurveSegments("serpentine").build(4, 4, 2)
    np.testing.assert_array_equal(d.process_pixels(0), [0, 1, 2, 3, 7, 6, 5, 4])
    d = CurveSegments("morton").build(4, 4, 4)
    assert d.owner_image().tolist() == [[0, 0, 1, 1], [0, 0, 1, 1], [2, 2, 3, 3], [2, 2, 3, 3]]
    # 10 pixels among 3: lengths 3, 3, 4 (differ by at most one)
    np.testing.assert_array_equal(CurveSegments("serpentine").build(5, 2, 3).task_lengths, [3, 3, 4])
    np.testing.assert_array_equal(CurveSegments("morton").build(5, 2, 1).task_pixels, morton_order(5, 2))
    np.testing.assert_array_equal(CurveSegments("serpentine").build(5, 2, 1).task_pixels, serpentine_order(5, 2))


def test_curve_tiles_tiny():
    # 2x2 grid of 2x2 tiles: Hilbert order of the grid visits tiles
    # (0,0), (0,1), (1,1), (1,0), i.e. top-left, bottom-left, bottom-right, top-right
    d = CurveTiles(tile=2).build(4, 4, 2)
    assert [d.task(t).tolist() for t in range(4)] == [[0, 1, 4, 5], [8, 9, 12, 13], [10, 11, 14, 15], [2, 3, 6, 7]]
    np.testing.assert_array_equal(d.task_process, [0, 1, 0, 1])
    assert d.owner_image().tolist() == [[0, 0, 1, 1], [0, 0, 1, 1], [1, 1, 0, 0], [1, 1, 0, 0]]
    # one tile covering the image: its Morton order (or scan order)
    np.testing.assert_array_equal(CurveTiles(tile=4).build(4, 4, 1).task_pixels, morton_order(4, 4))
    np.testing.assert_array_equal(CurveTiles(tile=4, inner="scan").build(4, 4, 1).task_pixels, np.arange(16))
    # a partial edge tile keeps the Morton order of its pixels
    np.testing.assert_array_equal(CurveTiles(tile=8).build(5, 3, 1).task_pixels, morton_order(5, 3))
    d = CurveTiles(tile=2, dynamic=True, dispatch_cycles=5).build(4, 4, 3)
    assert d.dynamic and d.dispatch_cycles == 5.0 and d.n_tasks == 4
    assert d.owner_image().tolist() == [[0, 0, 3, 3], [0, 0, 3, 3], [1, 1, 2, 2], [1, 1, 2, 2]]


# ---------------------------------------------------------------- users' own


def test_custom_from_owner_array():
    checker = CustomMapping("checker", lambda w, h, n: (np.add.outer(np.arange(h), np.arange(w)) % n))
    d = checker.build(4, 3, 2)
    assert d.name == "checker"
    assert d.owner_image().tolist() == [[0, 1, 0, 1], [1, 0, 1, 0], [0, 1, 0, 1]]
    np.testing.assert_array_equal(d.process_pixels(1), [1, 3, 4, 6, 9, 11])


def test_custom_from_pixel_lists_keeps_their_order():
    mapping = CustomMapping("backwards", lambda w, h, n: [np.arange(w * h)[::-1][p::n] for p in range(n)])
    d = mapping.build(3, 2, 2)
    np.testing.assert_array_equal(d.process_pixels(0), [5, 3, 1])
    np.testing.assert_array_equal(d.process_pixels(1), [4, 2, 0])


def test_coverage_kernel_matches_bincount():
    # The check of a distribution's pixels counts in one byte a pixel; its
    # figures must be a bincount's on seeded random arrays (with gaps and
    # repeats), and a count of 255 or more is reported as such.
    from coherence.distribution import _coverage

    rng = np.random.default_rng(11)
    for _ in range(200):
        n_pixels = int(rng.integers(1, 60))
        pixels = rng.integers(0, n_pixels, int(rng.integers(0, 2 * n_pixels))).astype(np.int64)
        counts = np.bincount(pixels, minlength=n_pixels)
        missing, repeated = np.flatnonzero(counts == 0), np.flatnonzero(counts > 1)
        expected = (missing.size, int(missing[0]) if missing.size else -1, repeated.size,
                    int(repeated[0]) if repeated.size else -1, int(counts[repeated[0]]) if repeated.size else 0)
        assert _coverage(pixels, n_pixels) == expected
    assert _coverage(np.zeros(300, dtype=np.int64), 2) == (1, 1, 1, 0, 255)
    with pytest.raises(ValueError, match="1 pixels assigned more than once .*255 times or more"):
        CustomMapping("many", lambda w, h, n: [np.r_[np.zeros(300, dtype=np.int64), 1]]).build(2, 1, 1)


def test_mappings_hand_their_arrays_over_frozen():
    # A mapping's fresh arrays go into its distribution read-only and without
    # a copy, and its coverage check counts in bytes: building P, R, B or DB
    # takes at most 33 bytes a pixel at its height (40-56 with a copy of each
    # array and a bincount). A caller's array, read-only or not, is copied.
    import tracemalloc

    for name, most in (("S", 9.5), ("P", 17.5), ("R", 17.5), ("B", 17.5), ("DB", 33.5)):
        mapping = get_mapping(name)
        mapping.build(16, 16, 8)  # compiled outside the measure
        tracemalloc.start()
        d = mapping.build(256, 256, 8)
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        assert peak <= most * 256 * 256, (name, peak / 256 ** 2)
        assert not d.task_pixels.flags.writeable
    mine = np.arange(4, dtype=np.int64)
    frozen = np.arange(4, dtype=np.int64)
    frozen.flags.writeable = False  # read-only, but its owner may write again
    for theirs in (mine, frozen):
        d = Distribution("theirs", 2, 2, 1, [0, 4], theirs, [0])
        theirs.flags.writeable = True
        theirs[0] = 3
        assert d.task_pixels[0] == 0


def test_custom_errors_name_what_is_wrong():
    with pytest.raises(ValueError, match=r"1 pixels missing \(first: pixel 3 \(x=1, y=1\)\)"):
        CustomMapping("m", lambda w, h, n: [np.array([0, 1]), np.array([2])]).build(2, 2, 2)
    with pytest.raises(ValueError, match=r"1 pixels assigned more than once \(first: pixel 2"):
        CustomMapping("m", lambda w, h, n: [np.array([0, 1, 2]), np.array([2, 3])]).build(2, 2, 2)
    with pytest.raises(ValueError, match=r"outside \[0, 4\)"):
        CustomMapping("m", lambda w, h, n: [np.array([0, 1, 2]), np.array([3, 4])]).build(2, 2, 2)
    with pytest.raises(ValueError, match="3 pixel arrays; expected one per process"):
        CustomMapping("m", lambda w, h, n: [[0], [1], [2, 3]]).build(2, 2, 2)
    with pytest.raises(ValueError, match=r"process ids must be in \[0, 2\); 1 pixels.*id 2"):
        CustomMapping("m", lambda w, h, n: np.array([[0, 1], [1, 2]])).build(2, 2, 2)
    with pytest.raises(ValueError, match=r"shape \(height, width\) = \(2, 3\), got \(3, 2\)"):
        CustomMapping("m", lambda w, h, n: np.zeros((3, 2), dtype=int)).build(3, 2, 2)
    with pytest.raises(ValueError, match="integer process ids"):
        CustomMapping("m", lambda w, h, n: np.zeros((2, 2))).build(2, 2, 2)
    with pytest.raises(ValueError, match="got dict"):
        CustomMapping("m", lambda w, h, n: {}).build(2, 2, 2)
    with pytest.raises(ValueError, match="CustomMapping.fn must be callable"):
        CustomMapping("m", 3)
    with pytest.raises(ValueError, match="CustomMapping.name"):
        CustomMapping("", lambda w, h, n: None)


def test_from_owner_image():
    image = np.array([[0, 0, 2], [1, 1, 2]])
    mapping = from_owner_image("mine", image)
    image[0, 0] = 2  # the mapping keeps its own copy
    d = mapping.build(3, 2, 3)
    assert d.owner_image().tolist() == [[0, 0, 2], [1, 1, 2]]
    assert mapping.build(3, 2, 5).process_pixel_counts().tolist() == [2, 2, 2, 0, 0]
    with pytest.raises(ValueError, match="fixed 3x2 owner image; cannot build it for 4x4"):
        mapping.build(4, 4, 3)
    with pytest.raises(ValueError, match=r"process ids must be in \[0, 2\)"):
        mapping.build(3, 2, 2)
    with pytest.raises(ValueError, match="must be a \\(height, width\\) array"):
        from_owner_image("flat", [0, 1])


# ---------------------------------------------------------------- validation


def test_parameters_are_validated():
    cases = [
        (lambda: Block(field=0), "Block.field must be >= 1"),
        (lambda: Block(field=2.5), "Block.field must be an integer"),
        (lambda: DynamicBlock(block=0), "DynamicBlock.block"),
        (lambda: DynamicBlock(dispatch_cycles=-1), "DynamicBlock.dispatch_cycles"),
        (lambda: DynamicBlock(dispatch_cycles=float("nan")), "DynamicBlock.dispatch_cycles"),
        (lambda: DynamicBlock(take_ahead=-1), "DynamicBlock.take_ahead"),
        (lambda: CurveSegments("peano"), "CurveSegments.curve"),
        (lambda: CurveTiles(tile=0), "CurveTiles.tile"),
        (lambda: CurveTiles(inner="hilbert"), "CurveTiles.inner"),
        (lambda: CurveTiles(dynamic=1), "CurveTiles.dynamic"),
        (lambda: CurveTiles(take_ahead=1), "CurveTiles.take_ahead"),
    ]
    for make, message in cases:
        with pytest.raises(ValueError, match=message):
            make()


@pytest.mark.parametrize("args,message", [
    ((0, 4, 2), "width must be >= 1"),
    ((4, -1, 2), "height must be >= 1"),
    ((4, 4, 0), "n_processes must be >= 1"),
    ((4, 4, True), "n_processes must be an integer"),
    ((4.0, 4, 2), "width must be an integer"),
])
def test_build_validates_sizes(args, message):
    for mapping in MAPPINGS.values():
        with pytest.raises(ValueError, match=message):
            mapping.build(*args)


def test_distribution_validates_its_csr():
    ok = dict(name="x", width=2, height=2, n_processes=2,
              task_offsets=[0, 2, 4], task_pixels=[0, 1, 2, 3], task_process=[0, 1])
    d = Distribution(**ok)
    assert d.n_tasks == 2 and not d.dynamic and d.task_process.dtype == np.int64
    assert "2 tasks, static" in repr(d)
    bad = [
        (dict(task_offsets=[1, 2, 4]), "start at 0"),
        (dict(task_offsets=[0, 3, 2, 4], task_process=[0, 1, 0]), "non-decreasing; task 1"),
        (dict(task_offsets=[0, 2, 3], task_pixels=[0, 1, 2]), "must hold width\\*height = 4 pixels"),
        (dict(task_pixels=[0, 1, 1, 3]), "1 pixels missing .*pixel 2.*1 pixels assigned more than once .*pixel 1"),
        (dict(task_pixels=[0, 1, 2, 9]), "outside"),
        (dict(task_pixels=[0.0, 1.0, 2.0, 3.0]), "must hold integers"),
        (dict(task_process=[0, 2]), "task 1 has process 2"),
        (dict(task_process=[0]), "one entry per task"),
        (dict(dispatch_cycles=5.0), "dynamic distributions only"),
        (dict(task_process=None, take_ahead=-1), "take_ahead must be >= 0"),
        (dict(n_processes=0), "n_processes must be >= 1"),
        (dict(name=""), "name must be a non-empty string"),
    ]
    for change, message in bad:
        with pytest.raises(ValueError, match=message):
            Distribution(**{**ok, **change})
    with pytest.raises(ValueError, match="process must be < n_processes"):
        d.process_pixels(2)
    with pytest.raises(ValueError, match="task must be < n_tasks"):
        d.task(2)


def test_distribution_arrays_are_private_and_read_only():
    offsets = np.array([0, 4])
    pixels = np.arange(4)
    d = Distribution("x", 2, 2, 1, offsets, pixels, np.zeros(1, dtype=np.int32))
    pixels[0] = 3
    assert d.task_pixels[0] == 0
    assert d.task_process.dtype == np.int64
    with pytest.raises(ValueError):
        d.task_pixels[0] = 1


# ---------------------------------------------------------------- pictures


def test_picture_static_and_dynamic():
    try:
        ax = Block().picture(4, width=64, height=64)
        assert len(ax.get_images()) == 1
        data = ax.get_images()[0].get_array()
        assert data.shape == (64, 64) and set(np.unique(data)) == {0, 1, 2, 3}
        assert ax.get_title() == "B: 4 processes"

        fig, given_ax = plt.subplots()
        assert DynamicBlock(block=8).picture(4, width=32, height=32, ax=given_ax) is given_ax
        assert "dynamic" in given_ax.get_title()
        assert len(given_ax.get_images()) == 1

        ax = Pixel().picture(30, width=16, height=8)  # colours repeat past 20
        assert ax.get_images()[0].get_array().max() < 20
    finally:
        plt.close("all")
