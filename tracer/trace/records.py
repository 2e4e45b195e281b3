"""The trace format's contract: record kinds, record packing and counters.

A *record* is one access to one scene record, packed into a uint32 as
``kind << KIND_SHIFT | write << WRITE_SHIFT | index`` (4-bit
:class:`RecordKind`, a write flag, 27-bit index). Records are reads unless
the write flag is set.
Writers (the tracer's kernels) and readers (layouts, simulation) use the
names here, never bare shifts, masks or counter positions: the compiled
helpers :func:`make_record`, :func:`record_kind` and :func:`record_id` inline
into kernels, and :class:`Counter` members are compile-time constants there.

Element primitives map to record kinds and test counters by offset:
``RecordKind.SPHERE + element_kind`` and ``Counter.TESTS_SPHERE +
element_kind`` (``tracer.scenes.model.ElementKind`` order: sphere, triangle,
polygon, patch, cone).
"""
from __future__ import annotations

import enum

import numpy as np
from numba import njit
from rtcommon.validate import InputError

KIND_SHIFT = 28
WRITE_SHIFT = 27
WRITE_FLAG = 1 << WRITE_SHIFT
INDEX_MASK = WRITE_FLAG - 1
#: The version this code writes: 2 added the counter ROOT_TESTS; 3 the texture kinds and counters;
#: 4 the auxiliary kind's plan (below) and the per-ray segments of path-traced traces
#: (``segments.npz``, :mod:`tracer.trace.segments`). A trace without segments is still written as
#: version 3, byte for byte as before, so every Whitted trace and its digest are unchanged.
FORMAT_VERSION = 4
#: The format versions a loader reads.
READABLE_VERSIONS = (3, 4)
#: The version written for a trace that has no per-ray segments.
PLAIN_FORMAT_VERSION = 3

# The budget of the 16 record kinds (4 bits), planned once for every workload:
#   0-8   in use: kd node, index entry, five primitive kinds, material, light;
#   9-12  in use: the study-era tracer's own data (workload study1997): ray-stack entry, hit
#         record, shading temporaries, frame-buffer pixel;
#   13-14 in use: textures (tracer.rendering.texture): texel (a global texel number across every
#         texture and mip level, 27 bits = 128 M texels) and texture header;
#   15    planned (format version 4): the auxiliary kind, AUXILIARY_KIND, shared by the records
#         that are not scene data and need few indices: its 27-bit index holds a 3-bit sub-kind
#         (AuxKind: a task counter, a ray state, a queue entry, four spare) and a 24-bit index
#         (AUX_INDEX_MASK; 16 M slots per sub-kind). Built and read with make_aux_record,
#         aux_kind and aux_index.
# A kind is added to RecordKind when its writer lands, with its counter.


class RecordKind(enum.IntEnum):
    """Kinds of scene records a pixel reads (4 bits in a packed record)."""

    KD_NODE = 0
    INDEX_ENTRY = 1
    SPHERE = 2
    TRIANGLE = 3
    POLYGON = 4
    PATCH = 5
    CONE = 6
    MATERIAL = 7
    LIGHT = 8
    # the study-era tracer's own data (Workload.log_ray_data); index: the
    # stack slot, the ray's depth - 1, the ray's depth - 1, the sample
    RAY_STACK = 9      #: a ray-stack entry: written by a push, read by a pop
    HIT_RECORD = 10    #: the hit record of a ray tree level: written by a trace, read by shading
    SHADING_TEMP = 11  #: shading temporaries of a level (hit point, normal, colour sum)
    FRAME_BUFFER = 12  #: a pixel of the frame buffer, written once
    # textures (tracer.rendering.texture); index: the texel's global number (textures one
    # after another, each level after level, each level row-major), the texture
    TEXEL = 13    #: one texel read by a texture lookup's filter
    TEXTURE = 14  #: a texture's header (size, levels, where its texels are), read once per lookup


N_KINDS = len(RecordKind)

#: The record kind whose index holds a sub-kind (:class:`AuxKind`) and a 24-bit index.
AUXILIARY_KIND = 15
AUX_KIND_SHIFT = 24
AUX_INDEX_MASK = (1 << AUX_KIND_SHIFT) - 1
N_AUX_KINDS = 1 << (WRITE_SHIFT - AUX_KIND_SHIFT)  # 8: three planned, five spare


class AuxKind(enum.IntEnum):
    """Sub-kinds of :data:`AUXILIARY_KIND` (3 bits of its index); 3-7 are spare."""

    TASK_COUNTER = 0  #: a dynamic mapping's shared task counter (index: the counter)
    RAY_STATE = 1     #: a ray's saved state in a ray order's buffer (index: the buffer slot)
    QUEUE_ENTRY = 2   #: an entry of a ray order's queue (index: the queue slot)


class Counter(enum.IntEnum):
    """Per-pixel counter columns of ``AccessTrace.counters``."""

    PRIMARY_RAYS = 0
    PRIMARY_HITS = 1
    SHADOW_RAYS = 2
    SHADOW_BLOCKED = 3
    REFLECTION_RAYS = 4
    REFLECTION_HITS = 5
    REFRACTION_RAYS = 6
    REFRACTION_HITS = 7
    NODE_VISITS = 8
    LEAF_VISITS = 9
    INDEX_READS = 10
    TESTS_SPHERE = 11
    TESTS_TRIANGLE = 12
    TESTS_POLYGON = 13
    TESTS_PATCH = 14
    TESTS_CONE = 15
    SHADING = 16
    LIGHT_READS = 17
    RAY_STACK_ACCESSES = 18
    HIT_RECORD_ACCESSES = 19
    SHADING_TEMP_ACCESSES = 20
    PIXEL_WRITES = 21
    #: intersection tests that took a square root (a sphere or cone whose
    #: quadratic has real roots); no record of its own, a subset of the tests
    ROOT_TESTS = 22
    TEXTURE_LOOKUPS = 23  #: filtered texture lookups (each reads its texture's header once)
    TEXEL_READS = 24      #: texels the lookups' filters read


# Column names of the counters, in column order (the on-disk format's names).
COUNTER_NAMES = tuple(c.name.lower() for c in Counter)
N_COUNTERS = len(Counter)

# Which counter equals the number of records of each kind.
COUNTER_OF_KIND = {
    RecordKind.KD_NODE: "node_visits",
    RecordKind.INDEX_ENTRY: "index_reads",
    RecordKind.SPHERE: "tests_sphere",
    RecordKind.TRIANGLE: "tests_triangle",
    RecordKind.POLYGON: "tests_polygon",
    RecordKind.PATCH: "tests_patch",
    RecordKind.CONE: "tests_cone",
    RecordKind.MATERIAL: "shading",
    RecordKind.LIGHT: "light_reads",
    RecordKind.RAY_STACK: "ray_stack_accesses",
    RecordKind.HIT_RECORD: "hit_record_accesses",
    RecordKind.SHADING_TEMP: "shading_temp_accesses",
    RecordKind.FRAME_BUFFER: "pixel_writes",
    RecordKind.TEXEL: "texel_reads",
    RecordKind.TEXTURE: "texture_lookups",
}


@njit(cache=True, inline="always")
def make_record(kind, index):
    """The packed uint32 record of ``index`` of ``kind``."""
    return np.uint32((np.int64(kind) << KIND_SHIFT) | np.int64(index))


@njit(cache=True, inline="always")
def record_kind(record):
    """The :class:`RecordKind` value of a packed record, as an int64."""
    return np.int64(record >> KIND_SHIFT)


@njit(cache=True, inline="always")
def record_is_write(record):
    """Whether a packed record is a write (its write flag is set)."""
    return (np.int64(record) & WRITE_FLAG) != 0


@njit(cache=True, inline="always")
def make_write_record(kind, index):
    """The packed uint32 record of a write to ``index`` of ``kind``."""
    return np.uint32((np.int64(kind) << KIND_SHIFT) | WRITE_FLAG | np.int64(index))


@njit(cache=True, inline="always")
def record_id(record):
    """The index part of a packed record, as an int64."""
    return np.int64(record & INDEX_MASK)


@njit(cache=True, inline="always")
def make_aux_record(aux_kind, index, write):
    """The packed uint32 record of ``index`` (< 2**24) of the :class:`AuxKind` ``aux_kind``."""
    flag = WRITE_FLAG if write else 0
    return np.uint32((np.int64(AUXILIARY_KIND) << KIND_SHIFT) | flag
                     | (np.int64(aux_kind) << AUX_KIND_SHIFT) | np.int64(index))


@njit(cache=True, inline="always")
def aux_kind(record):
    """The :class:`AuxKind` value of a record of :data:`AUXILIARY_KIND`, as an int64."""
    return (np.int64(record) & INDEX_MASK) >> AUX_KIND_SHIFT


@njit(cache=True, inline="always")
def aux_index(record):
    """The 24-bit index of a record of :data:`AUXILIARY_KIND`, as an int64."""
    return np.int64(record) & AUX_INDEX_MASK


def pack_aux(aux_kind, index, write=False) -> np.ndarray:
    """Pack auxiliary records (scalars or arrays) into uint32 records of :data:`AUXILIARY_KIND`.

    Raises
    ------
    ValueError
        If a sub-kind is outside ``0 .. 7`` or an index outside ``0 .. 2**24 - 1``.
    """
    sub = np.asarray(aux_kind, dtype=np.int64)
    index = np.asarray(index, dtype=np.int64)
    if np.any((sub < 0) | (sub >= N_AUX_KINDS)):
        raise InputError(f"pack_aux: aux_kind must be in 0..{N_AUX_KINDS - 1}")
    if np.any((index < 0) | (index > AUX_INDEX_MASK)):
        raise InputError(f"pack_aux: index must be in 0..{AUX_INDEX_MASK}")
    flag = np.where(np.asarray(write, dtype=bool), WRITE_FLAG, 0)
    return ((AUXILIARY_KIND << KIND_SHIFT) | flag | (sub << AUX_KIND_SHIFT) | index).astype(np.uint32)


def unpack_aux(records) -> tuple[np.ndarray, np.ndarray]:
    """Split auxiliary records into ``(aux_kind, index)`` arrays (uint8, uint32), dropping the write flag.

    Raises
    ------
    ValueError
        If a record is not of :data:`AUXILIARY_KIND`.
    """
    records = np.asarray(records, dtype=np.uint32)
    if np.any((records >> KIND_SHIFT) != AUXILIARY_KIND):
        raise InputError(f"unpack_aux: every record must be of the auxiliary kind {AUXILIARY_KIND}")
    index = records & np.uint32(INDEX_MASK)
    return (index >> AUX_KIND_SHIFT).astype(np.uint8), index & np.uint32(AUX_INDEX_MASK)


def pack(kind, index, write=False) -> np.ndarray:
    """Pack ``kind``, ``index`` and the write flag (scalars or arrays) into uint32 records.

    Raises
    ------
    ValueError
        If a kind is not a :class:`RecordKind` or an index is outside
        ``0 .. 2**27 - 1``.
    """
    kind = np.asarray(kind, dtype=np.int64)
    index = np.asarray(index, dtype=np.int64)
    if np.any((kind < 0) | (kind > max(RecordKind))):
        raise InputError(f"pack: kind must be a RecordKind value (0..{int(max(RecordKind))})")
    if np.any((index < 0) | (index > INDEX_MASK)):
        raise InputError(f"pack: index must be in 0..{INDEX_MASK}")
    flag = np.where(np.asarray(write, dtype=bool), WRITE_FLAG, 0)
    return ((kind << KIND_SHIFT) | flag | index).astype(np.uint32)


def unpack(records) -> tuple[np.ndarray, np.ndarray]:
    """Split uint32 records into ``(kind, index)`` arrays (uint8, uint32), dropping the write flag."""
    records = np.asarray(records, dtype=np.uint32)
    return (records >> KIND_SHIFT).astype(np.uint8), records & np.uint32(INDEX_MASK)
