"""The report's texture section: how texels behave in the caches, for textured scenes.

Three tables, each from every process's pixels replayed on a cold hierarchy of
its own (:mod:`coherence.kind_misses`) or from one texel stream:

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


def texture_section(trace, scene, layout, hierarchy, mappings, n_processes: int, cost) -> dict:
    """The section's tables (see the module docstring) as DataFrames.

    Parameters
    ----------
    trace : tracer.trace.access.AccessTrace
        Of a textured scene (``textures`` in its metadata).
    scene : Scene or None
        Gives polygons their vertex counts in the layout.
    layout : MemoryLayout
    hierarchy : Hierarchy
    mappings : sequence of Mapping
    n_processes : int
    cost : CostModel
        Decides who renders which block of a dynamic mapping.

    Returns
    -------
    dict with ``share``, ``layouts`` and ``curves`` DataFrames
    """
    from coherence.kind_misses import dedicated_task_owners, misses_by_kind_per_layout
    from coherence.studies import place_layout
    from coherence.texture_layout import TextureLayout

    if not trace.metadata.get("textures"):
        raise InputError("texture_section: the trace has no textures")
    base = layout.texels.label
    labels = [base, *[label for label in LAYOUTS if label != base]]
    placements = {label: place_layout(layout.with_texels(TextureLayout.from_label(label)), trace, scene)
                  for label in labels}
    frames = []
    for mapping in mappings:
        distribution = mapping.build(trace.width, trace.height, n_processes)
        owners = dedicated_task_owners(trace, distribution, hierarchy, placements[base], cost)
        frames.append(misses_by_kind_per_layout(trace, placements, hierarchy, distribution, owners)
                      .assign(mapping=mapping.name))
    by_kind = pd.concat(frames, ignore_index=True)
    texel = by_kind[by_kind["kind"] == "texel"].set_index(["layout", "mapping", "level"])
    every = by_kind.groupby(["layout", "mapping", "level"], sort=False)[["misses"]].sum()
    table = texel[["accesses", "misses"]].join(every.rename(columns={"misses": "misses_all"})).reset_index()
    layouts = table.assign(texel_hit_rate=1.0 - table["misses"] / table["accesses"])
    layouts = layouts[layouts["layout"].isin(LAYOUTS)][["layout", "mapping", "level", "texel_hit_rate"]]
    share = table[table["layout"] == base].rename(columns={"accesses": "texel_reads", "misses": "texel_misses"})
    share = share.assign(misses_per_texel_read=share["texel_misses"] / share["texel_reads"],
                         texture_miss_share=share["texel_misses"] / share["misses_all"])
    share = share[["mapping", "level", "texel_reads", "texel_misses", "misses_per_texel_read", "texture_miss_share"]]
    curves = pd.concat([_texel_curve(trace, placements[label], hierarchy).assign(layout=label) for label in LAYOUTS],
                       ignore_index=True)
    order = {label: k for k, label in enumerate(LAYOUTS)}
    layouts = layouts.sort_values("layout", key=lambda column: column.map(order), kind="stable")
    return {"share": share.reset_index(drop=True), "layouts": layouts.reset_index(drop=True),
            "curves": curves[["layout", "line_size", "size", "capacity_lines", "misses", "miss_ratio"]]}


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
