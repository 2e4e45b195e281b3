"""Where scene records live in memory: from (kind, index) records to byte addresses.

A :class:`MemoryLayout` gives each record kind of an access trace a size, an
alignment and, for polygons and patches, a size per vertex. Placing it for a
scene (:meth:`MemoryLayout.place`) lays the kinds out one after another from
``base`` (in kind order, texels last), each region starting on a
``region_align`` boundary, records packed in index order at their aligned
sizes. A record read touches every cache line its bytes span, so a 96-byte
triangle read costs three or four 32-byte lines.

Presets (:data:`LAYOUTS`): ``compact``, the float32 records of today's
tracer, ``alpha1997``, a 1990s C tracer's structs on the 64-bit Alpha, and
``malloc1997``, the same structs allocated one at a time in a 1990s heap
(a layout with a ``heap``: :mod:`coherence.malloc_image`). Their sizes are one
table, :data:`PRESET_RECORDS`; ``docs/memory_image.md`` shows it with the
reason for every size (a test keeps the two equal).

Texels are not packed in index order: the layout's
:class:`~coherence.texture_layout.TextureLayout` (``MemoryLayout.texels``:
row-major by default; tiled, Morton or blocked) places them, see
:meth:`MemoryLayout.place`. A custom layout that leaves ``texel`` and
``texture`` out gets the compact sizes.

Ray stack to frame buffer are the tracer's own per-ray data, logged only by the
``study1997`` workload (:mod:`tracer.rendering.workload`). The ``alpha1997`` sizes
follow the C struct rules spelled out in ``docs/memory_image.md``; they
were fixed before any fitting. The study's code is not public:
this is a plausible tracer of its time on the 64-bit Alpha, not its code.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from numba import njit

from coherence.malloc_image import HEAP_KINDS, CreationOrder, HeapModel, heap_blocks
from coherence.page_placement import PagePlacement, PageTable, identity_pages
from coherence.texture_layout import TextureLayout
from rtcommon.validate import InputError, require_int, require_power_of_two
from tracer.trace.records import INDEX_MASK, KIND_SHIFT, N_KINDS, RecordKind, record_id, record_kind

_VARIABLE = (RecordKind.POLYGON, RecordKind.PATCH)


@dataclass(frozen=True)
class RecordLayout:
    """Size of one record kind.

    Parameters
    ----------
    size : int
        Bytes of a record (of the fixed part, for polygons and patches).
    align : int
        Records start on multiples of this (a power of two).
    per_vertex : int
        Extra bytes per vertex (polygons and patches only).
    """

    size: int
    align: int = 8
    per_vertex: int = 0

    def __post_init__(self):
        for name in ("size", "align", "per_vertex"):
            require_int(f"RecordLayout.{name}", getattr(self, name), 0)
        if self.size + self.per_vertex < 1:
            raise InputError("RecordLayout.size must be >= 1 byte")
        require_power_of_two("RecordLayout.align", self.align)


#: Record sizes of the presets: kind -> (``compact``, ``alpha1997``), as
#: RecordLayout(bytes, alignment[, bytes per vertex]). ``docs/memory_image.md``
#: renders this table with the reason for each size.
PRESET_RECORDS = {
    "kd_node": (RecordLayout(8, 8), RecordLayout(40, 8)),
    "index_entry": (RecordLayout(4, 4), RecordLayout(16, 8)),
    "sphere": (RecordLayout(16, 16), RecordLayout(104, 8)),
    "triangle": (RecordLayout(36, 4), RecordLayout(176, 8)),
    "polygon": (RecordLayout(4, 4, 12), RecordLayout(112, 8, 24)),
    "patch": (RecordLayout(4, 4, 24), RecordLayout(112, 8, 48)),
    "cone": (RecordLayout(32, 16), RecordLayout(160, 8)),
    "material": (RecordLayout(32, 16), RecordLayout(88, 8)),
    "light": (RecordLayout(24, 8), RecordLayout(48, 8)),
    "ray_stack": (RecordLayout(44, 4), RecordLayout(96, 8)),
    "hit_record": (RecordLayout(16, 8), RecordLayout(72, 8)),
    "shading_temp": (RecordLayout(36, 4), RecordLayout(96, 8)),
    "frame_buffer": (RecordLayout(12, 4), RecordLayout(3, 1)),
    "texel": (RecordLayout(4, 4), RecordLayout(4, 4)),
    "texture": (RecordLayout(32, 8), RecordLayout(64, 8)),
}

#: Frame-buffer pixel sizes a layout may be given (:meth:`MemoryLayout.with_frame_buffer`): 8-bit RGB,
#: 8-bit RGBA and float32 RGBA.
FRAME_BUFFER_BYTES = (3, 4, 16)

# what a layout that does not name the texture kinds gets (the compact sizes)
_TEXTURE_DEFAULTS = {name: PRESET_RECORDS[name][0] for name in ("texel", "texture")}


@dataclass(frozen=True)
class MemoryLayout:
    """Record sizes per kind and where the regions start.

    Parameters
    ----------
    records : dict of str to RecordLayout
        One entry per :class:`tracer.trace.access.RecordKind` name (lower case:
        ``kd_node``, ``index_entry``, ``sphere``, ``triangle``, ``polygon``,
        ``patch``, ``cone``, ``material``, ``light``, ``ray_stack``,
        ``hit_record``, ``shading_temp``, ``frame_buffer``, and optionally
        ``texel`` and ``texture``, which default to 4 [4] and 32 [8] bytes).
    base : int
        Address of the first region.
    region_align : int
        Each kind's region starts on a multiple of this (a power of two).
    name : str
    texels : TextureLayout
        The order of texels in their region (row-major by default).
    heap : HeapModel, optional
        Allocate the scene's records (:data:`~coherence.malloc_image.HEAP_KINDS`)
        one at a time with this allocator, in the tracer's creation order,
        in a heap after the regions (whose places for those kinds stay
        unused); see :meth:`place`. None (the default): regions only.
    """

    records: dict = field(default_factory=dict)
    base: int = 0x10000000
    region_align: int = 4096
    name: str = "custom"
    texels: TextureLayout = field(default_factory=TextureLayout)
    heap: HeapModel | None = None

    def __post_init__(self):
        expected = {kind.name.lower() for kind in RecordKind}
        if isinstance(self.records, dict):
            object.__setattr__(self, "records", {**_TEXTURE_DEFAULTS, **self.records})
        if not isinstance(self.texels, TextureLayout):
            raise InputError(f"MemoryLayout.texels must be a TextureLayout, got {self.texels!r}")
        given = set(self.records)
        if given != expected:
            missing = sorted(expected - given)
            unknown = sorted(given - expected)
            raise InputError(f"MemoryLayout.records must name every record kind; missing {missing}, "
                             f"unknown {unknown}")
        for name, record in self.records.items():
            if not isinstance(record, RecordLayout):
                raise InputError(f"MemoryLayout.records[{name!r}] must be a RecordLayout")
            if record.per_vertex and RecordKind[name.upper()] not in _VARIABLE:
                raise InputError(f"MemoryLayout.records[{name!r}].per_vertex is only for polygons and patches")
        require_int("MemoryLayout.base", self.base, 0, 2**48 - 1)
        require_power_of_two("MemoryLayout.region_align", self.region_align)
        if self.heap is not None and not isinstance(self.heap, HeapModel):
            raise InputError(f"MemoryLayout.heap must be a HeapModel or None, got {self.heap!r}")

    def scaled(self, factor: int) -> "MemoryLayout":
        """This layout with every record ``factor`` times as many bytes (alignments kept).

        The what-if "what if the scene's records were bigger": a richer
        material, a double-precision vertex, a fatter node.
        """
        require_int("MemoryLayout.scaled: factor", factor, 1)
        records = {name: RecordLayout(record.size * int(factor), record.align, record.per_vertex * int(factor))
                   for name, record in self.records.items()}
        return MemoryLayout(records=records, base=self.base, region_align=self.region_align,
                            name=self.name if factor == 1 else f"{self.name} x{int(factor)}", texels=self.texels,
                            heap=self.heap)

    def with_texels(self, texels: TextureLayout) -> "MemoryLayout":
        """This layout with its texels in the order of ``texels``."""
        return MemoryLayout(records=dict(self.records), base=self.base, region_align=self.region_align,
                            name=self.name, texels=texels, heap=self.heap)

    def with_frame_buffer(self, pixel_bytes: int) -> "MemoryLayout":
        """This layout with frame-buffer pixels of ``pixel_bytes`` bytes (one of :data:`FRAME_BUFFER_BYTES`).

        3: packed 8-bit RGB; 4: RGBA; 16: four float32 channels. A pixel is
        aligned to the largest power of two dividing its size (3 -> 1), so
        that pixels lie packed side by side and one cache line holds several
        pixels, which threads writing neighbouring pixels then share. The
        layout keeps its name; a run records the size beside it.
        """
        if isinstance(pixel_bytes, bool) or pixel_bytes not in FRAME_BUFFER_BYTES:
            raise InputError(f"frame-buffer pixel size must be one of {', '.join(map(str, FRAME_BUFFER_BYTES))} "
                             f"bytes, got {pixel_bytes!r}")
        pixel_bytes = int(pixel_bytes)
        records = {**self.records, "frame_buffer": RecordLayout(pixel_bytes, pixel_bytes & -pixel_bytes)}
        return MemoryLayout(records=records, base=self.base, region_align=self.region_align, name=self.name,
                            texels=self.texels, heap=self.heap)

    def _texel_starts(self, count: int, stride: int, textures):
        """Offsets of ``count`` texels from their region's start, and the region's bytes."""
        if textures is None:
            raise InputError("the layout needs the textures' level sizes (textures=...) to place texels")
        offsets = self.texels.texel_offsets(textures)
        if offsets.shape[0] != count:
            raise InputError(f"record_counts has {count} texels but the textures' levels hold {offsets.shape[0]}")
        return offsets * stride, (int(offsets.max()) + 1) * stride

    def record(self, kind: RecordKind | str) -> RecordLayout:
        key = kind.name.lower() if isinstance(kind, RecordKind) else str(kind).lower()
        return self.records[key]

    def place(self, record_counts, vertex_counts=None, textures=None, creation=None) -> "PlacedLayout":
        """Addresses of every record of a scene.

        Parameters
        ----------
        record_counts : dict of RecordKind or str to int
            Number of records of each kind (kinds left out have none).
        vertex_counts : dict of RecordKind or str to array of int, optional
            Vertices of each polygon / patch, shape (count,); without it every
            polygon and patch is taken to have 4 vertices.
        textures : sequence of sequence of (int, int), optional
            Each texture's mip levels as ``(width, height)``, finest first (a
            trace's ``textures`` metadata); needed when there are texels. The
            texels are then placed by :attr:`texels`, each at its aligned size.
        creation : coherence.malloc_image.CreationOrder, optional
            Needed with a :attr:`heap`, and only then: every record of the
            heap's kinds once, in the order the tracer allocated them
            (:func:`coherence.malloc_image.trace_creation_order`). Each gets a
            block of the heap, which starts on the first page boundary after
            the regions; every other kind keeps its region's place.

        Returns
        -------
        PlacedLayout
        """
        if (creation is None) != (self.heap is None):
            raise InputError(f"layout {self.name!r}: " + ("a heap layout places records in their creation order; "
                             "give creation=, or use coherence.studies.place_layout(layout, trace, scene)"
                             if creation is None else "creation= is only for a layout with a heap"))
        counts = _by_kind(record_counts, "record_counts")
        vertices = _by_kind(vertex_counts or {}, "vertex_counts")
        kind_first = np.zeros(N_KINDS + 1, dtype=np.int64)
        starts, sizes = {}, {}
        address = _round_up(int(self.base), self.region_align)
        # Regions in kind order, but texels last: the texel order pads levels differently, and a
        # texel region of another size must not move any other record (their conflicts would
        # change with the texel order).
        for kind in sorted(RecordKind, key=lambda k: (k == RecordKind.TEXEL, k)):
            count = int(counts.get(kind, 0))
            if count < 0:
                raise InputError(f"record_counts[{kind.name.lower()}] must be >= 0, got {count}")
            record = self.record(kind)
            if kind in vertices:
                n_vertices = np.asarray(vertices[kind], dtype=np.int64)
                if n_vertices.shape != (count,) or (count and n_vertices.min() < 3):
                    raise InputError(f"vertex_counts[{kind.name.lower()}] must hold {count} counts >= 3")
            else:
                n_vertices = np.full(count, 4, dtype=np.int64)
            size = np.full(count, record.size, dtype=np.int64) + record.per_vertex * n_vertices
            stride = (size + record.align - 1) // record.align * record.align
            if kind == RecordKind.TEXEL and count:
                start, region = self._texel_starts(count, int(stride[0]), textures)
                start = start + address
            else:
                start = address + np.concatenate(([0], np.cumsum(stride)[:-1])).astype(np.int64) if count else \
                    np.zeros(0, dtype=np.int64)
                region = int(stride.sum())
            starts[kind] = start
            sizes[kind] = size
            address = _round_up(address + region, self.region_align)
        for kind in RecordKind:
            kind_first[kind + 1] = kind_first[kind] + sizes[kind].size
        record_start = np.concatenate([starts[kind] for kind in RecordKind])
        record_size = np.concatenate([sizes[kind] for kind in RecordKind])
        if self.heap is not None:
            address = self._place_heap(creation, record_start, record_size, kind_first, address)
        return PlacedLayout(self, record_start, record_size, kind_first, address)

    def _place_heap(self, creation, record_start, record_size, kind_first, heap_start) -> int:
        """Move the heap kinds' records of ``record_start`` into heap blocks; returns the heap's end."""
        if not isinstance(creation, CreationOrder):
            raise InputError(f"creation must be a coherence.malloc_image.CreationOrder, got {type(creation).__name__}")
        kind = np.asarray(creation.kind, dtype=np.int64)
        index = np.asarray(creation.index, dtype=np.int64)
        if kind.shape != index.shape or kind.ndim != 1:
            raise InputError("creation: kind and index must be 1-d arrays of one length")
        counts = np.diff(kind_first)
        heap_kinds = np.array([int(k) for k in HEAP_KINDS], dtype=np.int64)
        expected = int(counts[heap_kinds].sum())
        good = np.isin(kind, heap_kinds)
        good[good] &= (index[good] >= 0) & (index[good] < counts[kind[good]])
        rows = kind_first[kind[good]] + index[good]
        named = np.zeros(record_start.shape[0], dtype=np.bool_)  # each record named at least once
        named[rows] = True
        distinct = int(np.count_nonzero(named))
        if not good.all() or kind.size != expected or distinct != expected:
            names = ", ".join(f"{RecordKind(k).name.lower()} {int(counts[k])}" for k in heap_kinds)
            raise InputError(f"creation must name every record of the heap's kinds once ({names}); it names "
                             f"{kind.size} allocations, {int(good.sum())} of them records of those kinds, "
                             f"{distinct} distinct")
        blocks = heap_blocks(self.heap, record_size[rows], heap_start)
        record_start[rows] = blocks + self.heap.header
        top = blocks + self.heap.block_sizes(record_size[rows])
        return max(int(heap_start), int(top.max(initial=heap_start)))


class RecordPlacement(NamedTuple):
    """Where every record lives, as compiled code reads it (see :class:`PlacedLayout`).

    Attributes
    ----------
    record_start, record_size : ndarray of int64, shape (R,)
        Address and size of every record, kinds one after another.
    kind_first : ndarray of int64, shape (K + 1,)
        Records of kind ``k`` are rows ``kind_first[k]:kind_first[k + 1]``.
    max_size : int
        Bytes of the largest record (bounds the lines any record spans:
        :func:`coherence.record_lines.line_span_bound`).
    pages : PageTable
        Physical frames of the records' pages (empty: addresses are physical).
    """

    record_start: np.ndarray
    record_size: np.ndarray
    kind_first: np.ndarray
    max_size: int
    pages: PageTable


@dataclass(frozen=True)
class PlacedLayout:
    """A layout placed for one scene.

    Attributes
    ----------
    layout : MemoryLayout
    record_start, record_size : ndarray of int64, shape (R,)
        Address and size of every record, kinds one after another.
    kind_first : ndarray of int64, shape (K + 1,)
        Records of kind ``k`` are rows ``kind_first[k]:kind_first[k + 1]``.
    end : int
        First address after the last region (after the heap, for a layout
        with a heap).
    pages : PageTable
        Physical frames of the pages the regions span; empty (the default)
        when physical addresses are the virtual ones (:meth:`with_pages`).
    """

    layout: MemoryLayout
    record_start: np.ndarray
    record_size: np.ndarray
    kind_first: np.ndarray
    end: int
    pages: PageTable = field(default_factory=identity_pages)

    @property
    def placement(self) -> RecordPlacement:
        """The record addresses as one bundle for compiled code (:func:`coherence.record_lines.record_lines`)."""
        return RecordPlacement(self.record_start, self.record_size, self.kind_first,
                               int(self.record_size.max(initial=0)), self.pages)

    def with_pages(self, placement: PagePlacement, hierarchy) -> "PlacedLayout":
        """This layout with its pages placed in physical memory by ``placement``.

        Every line address it gives from then on (:meth:`addresses`,
        :func:`coherence.record_lines.record_lines_and_writes`, :func:`coherence.pixel_lines.pixel_lines`)
        is physical. The page colours are those of ``hierarchy``
        (:meth:`~coherence.page_placement.PagePlacement.colours`); a data TLB
        of ``hierarchy`` must use the placement's page size, so that it sees
        one entry per page as it would on virtual addresses.
        """
        if not isinstance(placement, PagePlacement):
            raise InputError(f"placement must be a PagePlacement, got {type(placement).__name__}")
        if not placement.translates:
            return self
        tlb = getattr(hierarchy, "tlb", None)
        if placement.translates and tlb is not None and tlb.page_size != placement.page_size:
            raise InputError(f"page placement with {placement.page_size}-byte pages needs a TLB of the same page "
                             f"size; {tlb.name} has {tlb.page_size}-byte pages")
        shift = placement.page_size.bit_length() - 1
        first_page = int(self.layout.base) >> shift
        n_pages = max(-(-int(self.end) >> shift) - first_page, 1)
        held = self.record_size > 0
        # +1 at each record's first page, -1 after its last: the running sum marks every page that holds data
        used = np.bincount((self.record_start[held] >> shift) - first_page, minlength=n_pages)
        after = ((self.record_start[held] + self.record_size[held] - 1) >> shift) - first_page + 1
        used = used - np.bincount(after[after < n_pages], minlength=n_pages)
        table = placement.table(np.cumsum(used) > 0, first_page, placement.colours(hierarchy))
        return PlacedLayout(self.layout, self.record_start, self.record_size, self.kind_first, self.end, table)

    @property
    def scene_bytes(self) -> int:
        """Bytes of all records (without padding between regions)."""
        return int(self.record_size.sum())

    def region_bytes(self) -> dict:
        """Bytes per kind (records only), by lower-case kind name."""
        return {kind.name.lower(): int(self.record_size[self.kind_first[kind]:self.kind_first[kind + 1]].sum())
                for kind in RecordKind}

    def check_records(self, records: np.ndarray) -> None:
        """Raise ValueError if a record names a kind or index outside this layout."""
        records = np.ascontiguousarray(records, dtype=np.uint32)
        limit = np.diff(self.kind_first)
        first = _first_bad_record(records, limit)  # one pass, no per-record temporaries
        if first < 0:
            return
        kind = int(records[first]) >> KIND_SHIFT
        if kind >= N_KINDS:
            raise InputError(f"record {first} has kind {kind}, which is not a RecordKind")
        raise InputError(f"record {first} is {RecordKind(kind).name.lower()} {int(records[first]) & INDEX_MASK}, "
                         f"but the layout holds only {int(limit[kind])} of that kind")

    def addresses(self, records, line_size: int) -> np.ndarray:
        """Byte addresses (uint64, (M,)) of the ``line_size`` lines each record touches, in order."""
        records = np.ascontiguousarray(records, dtype=np.uint32)
        shift = require_power_of_two("line_size", line_size).bit_length() - 1
        self.check_records(records)
        # an empty buffer is replaced by one of exactly the lines needed
        from coherence.record_lines import record_lines

        out, n_lines = record_lines(records, 0, records.shape[0], self.placement, shift, np.empty(0, dtype=np.uint64))
        return out[:n_lines]


def record_counts_of(trace) -> dict:
    """Records of each kind a trace's scene holds: from its metadata
    (``record_counts``) when the tracer stored it, else the largest index read
    plus one (regions of records never read then shrink, which moves later
    regions' addresses but not which lines conflict within a region)."""
    stored = trace.metadata.get("record_counts") if hasattr(trace, "metadata") else None
    if stored:
        return {RecordKind[key.upper()]: int(value) for key, value in stored.items()}
    return _max_index_plus_one(np.asarray(trace.records))


def _max_index_plus_one(records: np.ndarray) -> dict:
    counts = np.zeros(N_KINDS, dtype=np.int64)
    chunk = 1 << 24
    for start in range(0, records.size, chunk):
        part = np.asarray(records[start:start + chunk])
        kinds = (part >> np.uint32(KIND_SHIFT)).astype(np.int64)
        indices = (part & np.uint32(INDEX_MASK)).astype(np.int64) + 1
        np.maximum.at(counts, kinds, indices)
    return {kind: int(counts[kind]) for kind in RecordKind}


def _by_kind(mapping, what: str) -> dict:
    result = {}
    for key, value in mapping.items():
        try:
            kind = key if isinstance(key, RecordKind) else RecordKind[str(key).upper()]
        except KeyError:
            raise InputError(f"{what}: unknown record kind {key!r}") from None
        result[kind] = value
    return result


def _round_up(value: int, align: int) -> int:
    return (value + align - 1) // align * align


@njit(cache=True, nogil=True)
def _first_bad_record(records, kind_counts):
    """Index of the first record whose kind is not below ``kind_counts.size``
    or whose index is not below its kind's count; -1 when all are good."""
    n_kinds = kind_counts.shape[0]
    for i in range(records.shape[0]):
        kind = record_kind(records[i])
        if kind >= n_kinds or record_id(records[i]) >= kind_counts[kind]:
            return i
    return -1


def _compact() -> MemoryLayout:
    return MemoryLayout(name="compact", records={name: sizes[0] for name, sizes in PRESET_RECORDS.items()})


def _alpha1997() -> MemoryLayout:
    # docs/memory_image.md: DEC C on the Alpha (LP64), one struct per record
    return MemoryLayout(name="alpha1997", records={name: sizes[1] for name, sizes in PRESET_RECORDS.items()})


def _malloc1997() -> MemoryLayout:
    # docs/memory_image.md: the alpha1997 structs, each malloc'ed in the tracer's creation order
    return MemoryLayout(name="malloc1997", records={name: sizes[1] for name, sizes in PRESET_RECORDS.items()},
                        heap=HeapModel())


LAYOUTS = {"compact": _compact, "alpha1997": _alpha1997, "malloc1997": _malloc1997}

#: The memory layout a run uses unless told otherwise: today's compact records.
DEFAULT_LAYOUT = "compact"


def get_layout(name_or_layout) -> MemoryLayout:
    """A preset by name (``compact``, ``alpha1997``, ``malloc1997``) or a MemoryLayout."""
    if isinstance(name_or_layout, MemoryLayout):
        return name_or_layout
    try:
        return LAYOUTS[str(name_or_layout)]()
    except KeyError:
        raise InputError(f"unknown memory layout {name_or_layout!r}: use one of {', '.join(LAYOUTS)}") from None
