"""The report's texture section: how texels behave in the caches, for textured scenes.

Three tables: ``share`` and ``layouts`` from every process's pixels replayed
on a cold hierarchy of its own (:mod:`coherence.kind_misses`), or under a
platform from runs on its shared levels (:func:`shared_texel_table`, each
level summed over its instances); ``curves`` from one texel stream:

* ``share``: per mapping at the section's process count and per cache level,
  texel reads, texel misses, misses per texel read and the texels' share of
  all the level's misses, under the report's memory layout;
* ``layouts``: texel hit rates per level for each texel order
  (:data:`LAYOUTS`) and mapping, at that process count;
* ``curves``: miss-ratio curves (fully associative LRU, exact, from reuse
  distances) of the texel reads alone, in scan-line order, per texel order,
  at the first level's line size.

Figures: :func:`plot_texel_hit_rates` and :func:`plot_texel_curves`.
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from analyses.plots import _axes, _bytes_text
from rtcommon.validate import InputError

#: texel orders the section compares (TextureLayout labels)
LAYOUTS = ("linear", "tiled4", "morton", "blocked4x8")


def texture_section(trace, scene, layout, hierarchy, mappings, n_processes: int, cost, shared=None,
                    machine=None) -> dict:
    """The section's tables (see the module docstring) as DataFrames.

    Parameters
    ----------
    trace : tracer.trace.access.AccessTrace
        Of a textured scene (``textures`` in its metadata).
    scene : Scene or None
        Gives polygons their vertex counts in the layout.
    layout : MemoryLayout
    hierarchy : Hierarchy
        The levels each process replays its pixels on when ``shared`` is None; the curves take its first
        level's line size and reach four times its largest level (with ``shared``, those of the shared
        levels' whole hierarchy, as the report's other curves; ``hierarchy`` is then not read).
    mappings : sequence of Mapping
    n_processes : int
    cost : CostModel
        Decides who renders which block of a dynamic mapping.
    shared : coherence.shared_run.SharedLevels, optional
        A platform's shared levels: ``share`` and ``layouts`` then come from one
        :func:`coherence.shared_run.simulate_shared_run` per texel order and mapping on them, each level's
        counts summed over its instances (:func:`coherence.kind_misses.shared_misses_by_kind`).
    machine : coherence.simulation.Machine, optional
        The operating system's machine of those runs (``n_cpus`` the platform's hardware threads);
        required with ``shared``.

    Returns
    -------
    dict with ``share``, ``layouts`` and ``curves`` DataFrames
    """
    from coherence.studies import place_layout
    from coherence.texture_layout import TextureLayout

    if not trace.metadata.get("textures"):
        raise InputError("texture_section: the trace has no textures")
    if shared is not None and machine is None:
        raise InputError("texture_section: runs on shared levels need the machine (machine)")
    base = layout.texels.label
    labels = [base, *[label for label in LAYOUTS if label != base]]
    placements = {label: place_layout(layout.with_texels(TextureLayout.from_label(label)), trace, scene)
                  for label in labels}
    if shared is None:
        table = _private_texel_table(trace, placements, hierarchy, mappings, n_processes, cost)
    else:
        table = shared_texel_table(trace, placements, shared, machine, mappings, n_processes, cost)
    layouts = table.assign(texel_hit_rate=1.0 - table["misses"] / table["accesses"])
    layouts = layouts[layouts["layout"].isin(LAYOUTS)][["layout", "mapping", "level", "texel_hit_rate"]]
    share = table[table["layout"] == base].rename(columns={"accesses": "texel_reads", "misses": "texel_misses"})
    share = share.assign(misses_per_texel_read=share["texel_misses"] / share["texel_reads"],
                         texture_miss_share=share["texel_misses"] / share["misses_all"])
    share = share[["mapping", "level", "texel_reads", "texel_misses", "misses_per_texel_read", "texture_miss_share"]]
    reach = hierarchy if shared is None else shared.hierarchy
    curves = pd.concat([_texel_curve(trace, placements[label], reach).assign(layout=label) for label in LAYOUTS],
                       ignore_index=True)
    order = {label: k for k, label in enumerate(LAYOUTS)}
    layouts = layouts.sort_values("layout", key=lambda column: column.map(order), kind="stable")
    return {"share": share.reset_index(drop=True), "layouts": layouts.reset_index(drop=True),
            "curves": curves[["layout", "line_size", "size", "capacity_lines", "misses", "miss_ratio"]]}


def _private_texel_table(trace, placements: dict, hierarchy, mappings, n_processes: int, cost) -> pd.DataFrame:
    """Texel accesses and misses and every kind's misses per (layout, mapping, level), each process's pixels
    on a cold ``hierarchy`` of its own (:func:`coherence.kind_misses.misses_by_kind_per_layout`)."""
    from coherence.kind_misses import dedicated_task_owners, misses_by_kind_per_layout

    base = next(iter(placements))
    frames = []
    for mapping in mappings:
        distribution = mapping.build(trace.width, trace.height, n_processes)
        owners = dedicated_task_owners(trace, distribution, hierarchy, placements[base], cost)
        frames.append(misses_by_kind_per_layout(trace, placements, hierarchy, distribution, owners)
                      .assign(mapping=mapping.name))
    by_kind = pd.concat(frames, ignore_index=True)
    texel = by_kind[by_kind["kind"] == "texel"].set_index(["layout", "mapping", "level"])
    every = by_kind.groupby(["layout", "mapping", "level"], sort=False)[["misses"]].sum()
    return texel[["accesses", "misses"]].join(every.rename(columns={"misses": "misses_all"})).reset_index()


def shared_texel_table(trace, placements: dict, levels, machine, mappings, n_processes: int, cost) -> pd.DataFrame:
    """Texel accesses and misses and the level's misses per (layout, mapping, level), from one run on shared
    levels per placement and mapping.

    Parameters
    ----------
    trace : tracer.trace.access.AccessTrace
    placements : dict of str to PlacedLayout
        Labelled placements (one per texel order).
    levels : coherence.shared_run.SharedLevels
        The shared levels every run is simulated on, and their interleaving.
    machine : coherence.simulation.Machine
        The operating system's machine of every run (``n_cpus`` the levels' hardware threads).
    mappings : sequence of Mapping
    n_processes : int
    cost : CostModel

    Returns
    -------
    DataFrame
        ``layout``, ``mapping``, ``level``, ``accesses`` and ``misses`` (the texel reads that reached the
        level and those it missed, summed over the level's instances), ``misses_all`` (the misses of the
        processes' own accesses at the level, the study's ``<level>_misses`` summed: background reads left
        out); rows mapping by mapping, then placement, then level, a level no texel read reached left out.
    """
    from coherence.kind_misses import shared_misses_by_kind
    from coherence.shared_run import pixel_pieces, simulate_shared_run
    from tracer.trace.access import COUNTER_NAMES

    names = levels.hierarchy.level_names
    compute = cost.compute_cycles(trace.counters, COUNTER_NAMES)
    rows = []
    for label, placed in placements.items():
        pieces = pixel_pieces(trace, placed, levels.hierarchy.levels[0].line_size)
        for k, mapping in enumerate(mappings):
            run = simulate_shared_run(trace, mapping.build(trace.width, trace.height, n_processes), levels.machine,
                                      placed, cost, machine, interleave_cycles=levels.interleave_cycles,
                                      compute=compute, pieces=pieces)
            by_kind = shared_misses_by_kind(run.shared)
            texel = by_kind[by_kind["kind"] == "texel"].set_index("level")
            processes = run.run.processes
            for level in names:
                if level in texel.index:  # as misses_by_kind: no row for a level no texel read reached
                    rows.append((k, label, mapping.name, level, int(texel.loc[level, "accesses"]),
                                 int(texel.loc[level, "misses"]), int(processes[f"{level}_misses"].sum())))
        del pieces
    table = pd.DataFrame(rows, columns=["order", "layout", "mapping", "level", "accesses", "misses", "misses_all"])
    return table.sort_values("order", kind="stable").drop(columns="order").reset_index(drop=True)


def _texel_curve(trace, placed, hierarchy) -> pd.DataFrame:
    """Miss-ratio curve of the texel reads alone, scan-line order, at the first level's line size."""
    from cachesim import ReuseCounter
    from tracer.trace.records import KIND_SHIFT, RecordKind

    line_size = hierarchy.levels[0].line_size
    records = np.asarray(trace.records)
    counter = ReuseCounter(line_size)
    piece = 1 << 22
    for start in range(0, records.size, piece):
        part = records[start:start + piece]
        texels = part[(part >> np.uint32(KIND_SHIFT)) == RecordKind.TEXEL]
        counter.update(placed.addresses(texels, line_size))
    top = 4 * max(level.size for level in hierarchy.levels)
    sizes = line_size * 2 ** np.arange(int(np.log2(top // line_size)) + 1)
    return counter.profile().miss_ratio_curve(sizes.astype(np.int64)).assign(line_size=line_size)


def plot_texel_hit_rates(df, level: str = "L1", ax=None):
    """Texel hit rate at ``level`` per texel order (bars) and mapping (groups).

    ``df``: the ``layouts`` table of :func:`texture_section`.
    """
    ax = _axes(ax, (6.5, 4))
    rows = df[df["level"] == level]
    mappings = list(dict.fromkeys(rows["mapping"]))
    layouts = list(dict.fromkeys(rows["layout"]))
    width = 0.8 / max(1, len(layouts))
    for k, label in enumerate(layouts):
        values = rows[rows["layout"] == label].set_index("mapping").reindex(mappings)["texel_hit_rate"]
        ax.bar(np.arange(len(mappings)) - 0.4 + (k + 0.5) * width, values, width, label=label)
    ax.set_xticks(range(len(mappings)), mappings)
    ax.set_ylabel(f"texel hit rate at {level}")
    ax.set_ylim(0, 1.15)
    ax.legend(fontsize=8, ncol=len(layouts), loc="upper center")
    return ax


def plot_texel_curves(df, ax=None):
    """Miss ratio of the texel stream against cache size, one line per texel order.

    ``df``: the ``curves`` table of :func:`texture_section`.
    """
    from matplotlib.ticker import FuncFormatter

    ax = _axes(ax, (6.5, 4))
    for label, rows in df.groupby("layout", sort=False):
        ax.plot(rows["size"], rows["miss_ratio"], marker=".", label=label)
    ax.set_xscale("log", base=2)
    ax.xaxis.set_major_formatter(FuncFormatter(lambda value, _: _bytes_text(value)))
    ax.set_xlabel("cache size (fully associative LRU)")
    ax.set_ylabel("texel miss ratio")
    ax.legend(fontsize=8)
    return ax
