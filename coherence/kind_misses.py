"""Which record kinds the misses belong to: texture misses beside scene misses.

:func:`misses_by_kind` replays each process's pixels, in the order it renders
them, through a cold hierarchy of its own, and splits every level's accesses
and misses by the record kind each access came from. It answers "how many of
the misses are texels, and how often does a texel read miss" per mapping and
layout. It is the dedicated-CPU case of the schedule (as many CPUs as
processes, no time slicing, no background load), which is what a texture
study compares; the schedule simulation (:mod:`coherence.simulation`) counts
misses per process, not per kind.
"""
from __future__ import annotations

import numpy as np
import pandas as pd
from numba import njit

from cachesim import Hierarchy
from cachesim.simulate import simulate
from coherence.layout import PlacedLayout
from tracer.trace.records import INDEX_MASK, KIND_SHIFT, N_KINDS, WRITE_FLAG, RecordKind
from rtcommon.validate import InputError


def process_pixels(distribution, task_owner=None) -> list[np.ndarray]:
    """Each process's pixels in the order it renders them.

    Parameters
    ----------
    distribution : coherence.distribution.Distribution
    task_owner : ndarray of int64, shape (T,), optional
        The process that rendered each task (:attr:`coherence.simulation.Run.task_owner`);
        required for a dynamic distribution, default the static owners.

    Returns
    -------
    list of ndarray of int64
        Pixel numbers (row-major) per process.
    """
    owner = np.asarray(distribution.task_process if task_owner is None else task_owner, dtype=np.int64)
    if owner.shape != (distribution.n_tasks,) or (owner.size and owner.min() < 0):
        raise InputError("process_pixels: a dynamic distribution needs the task owners of a run (task_owner)")
    sizes = np.diff(distribution.task_offsets)
    pixel_owner = np.repeat(owner, sizes)
    pixels = np.asarray(distribution.task_pixels, dtype=np.int64)
    order = np.argsort(pixel_owner, kind="stable")  # task order within each process
    bounds = np.searchsorted(pixel_owner[order], np.arange(distribution.n_processes + 1))
    return [pixels[order[bounds[p]:bounds[p + 1]]] for p in range(distribution.n_processes)]


def dedicated_task_owners(trace, distribution, hierarchy: Hierarchy, placed: PlacedLayout, cost):
    """Who rendered each task of a dynamic ``distribution`` with a CPU per process and no
    other load (one :func:`~coherence.simulation.simulate_run`), for :func:`process_pixels`;
    None for a static distribution, whose owners are fixed."""
    if not distribution.dynamic:
        return None
    from coherence.simulation import Machine, simulate_run

    return simulate_run(trace, distribution, hierarchy, placed, cost,
                        Machine(n_cpus=distribution.n_processes, background_load=0)).task_owner


@njit(cache=True, nogil=True)
def gather_records(pixel_offsets, records, order, out):
    """Copy the records of the pixels ``order`` (int64, (K,)), one pixel after another, to the
    front of ``out`` (uint32, long enough); returns how many were copied."""
    k = 0
    for i in range(order.size):
        p = order[i]
        for j in range(pixel_offsets[p], pixel_offsets[p + 1]):
            out[k] = records[j]
            k += 1
    return k


def pixel_records(trace, pixels: np.ndarray) -> np.ndarray:
    """The records of ``pixels`` (in that order), concatenated, uint32."""
    offsets = np.asarray(trace.pixel_offsets, dtype=np.int64)
    pixels = np.ascontiguousarray(pixels, dtype=np.int64)
    out = np.empty(int((offsets[pixels + 1] - offsets[pixels]).sum()), dtype=np.uint32)
    gather_records(offsets, np.asarray(trace.records), pixels, out)
    return out


def lines_and_kinds(records: np.ndarray, placed: PlacedLayout, line_size: int):
    """Byte addresses of the lines ``records`` touch (as :meth:`PlacedLayout.addresses`),
    the record kind of each and whether it is a write: uint64, uint8 and bool
    arrays of one length."""
    records = np.ascontiguousarray(records, dtype=np.uint32)
    placed.check_records(records)
    kinds = (records >> np.uint32(KIND_SHIFT)).astype(np.int64)
    rows = placed.kind_first[kinds] + (records & np.uint32(INDEX_MASK)).astype(np.int64)
    shift = int(line_size).bit_length() - 1
    first = placed.record_start[rows] >> shift
    spans = ((placed.record_start[rows] + placed.record_size[rows] - 1) >> shift) - first + 1
    within = np.arange(int(spans.sum()), dtype=np.int64) - np.repeat(np.cumsum(spans) - spans, spans)
    lines = np.repeat(first, spans) + within
    writes = np.repeat((records & np.uint32(WRITE_FLAG)) != 0, spans)
    return (lines << shift).astype(np.uint64), np.repeat(kinds, spans).astype(np.uint8), writes


def misses_by_kind(trace, placed: PlacedLayout, hierarchy: Hierarchy, distribution, task_owner=None) -> pd.DataFrame:
    """Accesses and misses per cache level and record kind, summed over processes.

    Parameters
    ----------
    trace : tracer.trace.access.AccessTrace
    placed : PlacedLayout
    hierarchy : Hierarchy
        Every process gets a cold copy.
    distribution : coherence.distribution.Distribution
    task_owner : ndarray of int64, optional
        See :func:`process_pixels`.

    Returns
    -------
    DataFrame
        One row per (level, kind) with any accesses: ``level`` (name),
        ``kind`` (lower-case :class:`~tracer.trace.records.RecordKind` name),
        ``accesses``, ``misses`` (accesses the level did not serve).
    """
    table = misses_by_kind_per_layout(trace, {"": placed}, hierarchy, distribution, task_owner)
    return table.drop(columns="layout")


def misses_by_kind_per_layout(trace, placements: dict, hierarchy: Hierarchy, distribution,
                              task_owner=None) -> pd.DataFrame:
    """:func:`misses_by_kind` for several placements of one trace at once.

    Each process's records are gathered and turned into lines once; when the
    placements differ only in where texels live and every texel takes one
    line, only the texel addresses are redone for each placement.

    Parameters
    ----------
    placements : dict of str to PlacedLayout
        Labelled placements (for example one per texel order).

    Returns
    -------
    DataFrame
        :func:`misses_by_kind`'s columns after a first one, ``layout`` (the label).
    """
    labels = list(placements)
    first = placements[labels[0]]
    line_size = min(level.line_size for level in hierarchy.levels)
    shift = int(line_size).bit_length() - 1
    n_levels = len(hierarchy.levels)
    accesses = np.zeros((len(labels), n_levels, N_KINDS), dtype=np.int64)
    misses = np.zeros_like(accesses)
    patchable = [_only_texels_move(first, placements[label], line_size) for label in labels]
    texel_first = first.kind_first[RecordKind.TEXEL]
    for pixels in process_pixels(distribution, task_owner):
        records = pixel_records(trace, pixels)
        addresses, kinds, writes = lines_and_kinds(records, first, line_size)
        if addresses.size == 0:
            continue
        texel_lines = kinds == RecordKind.TEXEL
        texel_rows = texel_first + (records[(records >> np.uint32(KIND_SHIFT)) == RecordKind.TEXEL]
                                    & np.uint32(INDEX_MASK)).astype(np.int64)
        for k, label in enumerate(labels):
            placed = placements[label]
            if patchable[k]:
                addresses[texel_lines] = ((placed.record_start[texel_rows] >> shift) << shift).astype(np.uint64)
                stream = (addresses, kinds, writes)
            else:
                stream = lines_and_kinds(records, placed, line_size)
            served = simulate(stream[0], hierarchy, writes=stream[2], return_levels=True).served_by
            for level in range(n_levels):
                accesses[k, level] += np.bincount(stream[1][served >= level], minlength=N_KINDS)
                misses[k, level] += np.bincount(stream[1][served > level], minlength=N_KINDS)
    rows = [{"layout": label, "level": hierarchy.levels[level].name, "kind": RecordKind(kind).name.lower(),
             "accesses": int(accesses[k, level, kind]), "misses": int(misses[k, level, kind])}
            for k, label in enumerate(labels) for level in range(n_levels) for kind in range(N_KINDS)
            if accesses[k, level, kind]]
    return pd.DataFrame(rows, columns=["layout", "level", "kind", "accesses", "misses"])


def _only_texels_move(first: PlacedLayout, other: PlacedLayout, line_size: int) -> bool:
    """Whether ``other`` places every record as ``first`` does but texels, and
    every texel of both takes exactly one line (so texel addresses can be
    swapped in without changing the stream's length)."""
    if other is first:
        return True
    lo, hi = first.kind_first[RecordKind.TEXEL], first.kind_first[RecordKind.TEXEL + 1]
    if not (np.array_equal(first.kind_first, other.kind_first)
            and np.array_equal(first.record_start[:lo], other.record_start[:lo])
            and np.array_equal(first.record_start[hi:], other.record_start[hi:])
            and np.array_equal(first.record_size, other.record_size)):
        return False
    for placed in (first, other):
        starts, sizes = placed.record_start[lo:hi], placed.record_size[lo:hi]
        if np.any(starts // line_size != (starts + sizes - 1) // line_size):
            return False
    return True


def shared_misses_by_kind(shared) -> pd.DataFrame:
    """Accesses and misses per cache level and record kind of a run on shared levels, each level summed
    over its instances.

    Parameters
    ----------
    shared : cachesim.multicore_state.SharedResult
        A run's machine counts (:attr:`coherence.shared_run.SharedRun.shared`), given record kinds.

    Returns
    -------
    DataFrame
        :func:`misses_by_kind`'s columns: one row per (level, kind) with any accesses at that level (an
        access reaches a level when the levels above it missed). The auxiliary kind (a dynamic mapping's
        task counter) is ``auxiliary``; kind 0 (``kd_node``) also holds background reads, if the run had
        any.
    """
    from cachesim.sets import ACCESSES, MISSES

    if not shared.by_kind:
        raise InputError("shared_misses_by_kind: the run's counts were not kept per record kind")
    counts = shared.counts.sum(axis=1)  # (L, kinds, counters)
    names = [kind.name.lower() for kind in RecordKind] + ["auxiliary"] * (counts.shape[1] - N_KINDS)
    rows = [{"level": level_name, "kind": names[kind], "accesses": int(counts[level, kind, ACCESSES]),
             "misses": int(counts[level, kind, MISSES])}
            for level, level_name in enumerate(shared.machine.hierarchy.level_names)
            for kind in range(counts.shape[1]) if counts[level, kind, ACCESSES]]
    return pd.DataFrame(rows, columns=["level", "kind", "accesses", "misses"])


def texture_summary(by_kind: pd.DataFrame, level_misses: dict | None = None) -> dict:
    """Per level of ``by_kind`` (:func:`misses_by_kind` or :func:`shared_misses_by_kind`):
    ``texel_<level>_misses_per_access`` (misses of texel reads over the texel reads that reached the level)
    and ``texture_<level>_miss_share`` (texel misses over all the level's misses).

    ``level_misses`` (level name to a count), when given, are the levels' misses the share divides by (a
    run on shared levels: the processes' own, leaving out background reads, which its kind 0 holds); by
    default the sum of ``by_kind``'s misses at the level."""
    out = {}
    for level, rows in by_kind.groupby("level", sort=False):
        texel = rows[rows["kind"] == "texel"]
        texel_accesses = int(texel["accesses"].sum())
        texel_misses = int(texel["misses"].sum())
        all_misses = int(rows["misses"].sum()) if level_misses is None else int(level_misses[level])
        out[f"texel_{level}_misses_per_access"] = texel_misses / texel_accesses if texel_accesses else np.nan
        out[f"texture_{level}_miss_share"] = texel_misses / all_misses if all_misses else np.nan
    return out
