"""Figures of the coherence report: each takes a table (or an image) and an axes.

The functions draw and compute nothing (docs/design.md, "Conventions"): every value they show
is a column of the DataFrame they receive, built by :mod:`analyses.report`.
Each returns the axes it drew on, creating a figure when ``ax`` is None.
Mappings keep one colour across figures: the n-th mapping in the table's
order (or in ``order``) gets the n-th colour of matplotlib's ``tab10``.
"""
from __future__ import annotations

import numpy as np

__all__ = [
    "plot_image", "plot_scene_bytes", "plot_level_metric", "plot_miss_ratio_curves", "plot_cost_map",
    "plot_process_times", "plot_speedup", "plot_speedup_panels", "plot_miss_map", "mapping_colours",
]


def _axes(ax, figsize=(6.0, 4.0)):
    """``ax``, or the axes of a new pyplot figure: a notebook user calling ``plot_x(df)`` sees it inline.

    pyplot is imported only then, and the backend is left as it is (only the
    command line picks one).
    """
    if ax is not None:
        return ax
    import matplotlib.pyplot as plt

    _, ax = plt.subplots(figsize=figsize)
    return ax


def mapping_colours(names) -> dict:
    """Colour of each name, in order (tab10, repeating after ten)."""
    import matplotlib

    colours = list(matplotlib.colormaps["tab10"].colors)
    return {name: colours[index % len(colours)] for index, name in enumerate(names)}


def _names(df, column, order):
    present = list(dict.fromkeys(df[column]))
    if order is None:
        return present
    return [name for name in order if name in present] + [name for name in present if name not in order]


def _mark_caches(ax, caches, axis="x"):
    """Vertical (or horizontal) lines at each cache size; ``caches`` has level and size."""
    if caches is None:
        return
    for level, size in zip(caches["level"], caches["size"]):
        line = ax.axvline if axis == "x" else ax.axhline
        line(size, color="0.35", linestyle=":", linewidth=1)
        if axis == "x":
            ax.annotate(f"{level} {_bytes_text(size)}", xy=(size, 1.0), xycoords=("data", "axes fraction"),
                        xytext=(2, -10), textcoords="offset points", fontsize=8, color="0.25")
        else:
            ax.annotate(f"{level} {_bytes_text(size)}", xy=(1.0, size), xycoords=("axes fraction", "data"),
                        xytext=(-4, 2), textcoords="offset points", fontsize=8, color="0.25", ha="right")


def _bytes_text(size) -> str:
    size = float(size)
    for unit, scale in (("MB", 2**20), ("KB", 2**10)):
        if size >= scale:
            value = size / scale
            return f"{value:.0f} {unit}" if value == int(value) else f"{value:.1f} {unit}"
    return f"{size:.0f} B"


def plot_image(image, ax=None, *, title=None):
    """Show an RGB image (H, W, 3) in [0, 1] (values outside are clipped) without ticks."""
    ax = _axes(ax, (4.0, 4.0))
    ax.imshow(np.clip(np.asarray(image, dtype=np.float64), 0.0, 1.0), interpolation="nearest")
    ax.set_xticks([])
    ax.set_yticks([])
    if title:
        ax.set_title(title)
    return ax


def plot_scene_bytes(df, ax=None, *, caches=None):
    """Horizontal bars of bytes of scene data per record kind, cache sizes marked.

    Parameters
    ----------
    df : DataFrame
        Columns ``kind`` and ``bytes`` (one row per kind, ``total`` included
        if wanted).
    caches : DataFrame, optional
        Columns ``level`` and ``size`` (bytes): drawn as vertical lines.
    """
    ax = _axes(ax, (6.0, 3.2))
    positions = np.arange(len(df))
    ax.barh(positions, df["bytes"], color="tab:blue")
    ax.set_yticks(positions, list(df["kind"]))
    ax.invert_yaxis()
    ax.set_xscale("log")
    ax.set_xlabel("bytes of scene records (log scale)")
    _mark_caches(ax, caches, "x")
    ax.set_title("scene data against the cache sizes", fontsize=10)
    return ax


def plot_level_metric(df, ax=None, *, metric="misses_per_ray", order=None, log=True):
    """Grouped bars of a per-level metric: groups are cache levels, bars are (mapping, n).

    Parameters
    ----------
    df : DataFrame
        Columns ``mapping``, ``n_processes``, ``level`` and ``metric``.
    metric : str
        Column to draw (e.g. ``misses_per_ray``, ``miss_rate``, ``hit_rate``).
    order : sequence of str, optional
        Mapping order (colours).
    log : bool
        Logarithmic y axis.
    """
    ax = _axes(ax, (7.0, 3.6))
    names = _names(df, "mapping", order)
    colours = mapping_colours(names)
    counts = sorted(set(int(n) for n in df["n_processes"]))
    levels = list(dict.fromkeys(df["level"]))
    bars = [(name, n) for name in names for n in counts]
    width = 0.8 / max(len(bars), 1)
    hatches = ["", "//", "..", "xx"]
    for index, (name, n) in enumerate(bars):
        rows = df[(df["mapping"] == name) & (df["n_processes"] == n)].set_index("level")
        values = [rows[metric].get(level, np.nan) for level in levels]
        x = np.arange(len(levels)) - 0.4 + width * (index + 0.5)
        ax.bar(x, values, width, color=colours[name], hatch=hatches[counts.index(n) % len(hatches)],
               edgecolor="white", linewidth=0.3, label=f"{name}, n={n}")
    ax.set_xticks(np.arange(len(levels)), levels)
    if log:
        ax.set_yscale("log")
    ax.set_ylabel(metric.replace("_", " "))
    ax.legend(fontsize=7, ncol=max(1, len(counts)), frameon=False)
    return ax


def plot_miss_ratio_curves(df, ax=None, *, caches=None):
    """Miss ratio of a fully associative LRU cache against its size, one curve per order.

    Parameters
    ----------
    df : DataFrame
        Columns ``order``, ``line_size``, ``size`` (bytes), ``miss_ratio``.
        Several line sizes give solid (largest) and dashed curves.
    caches : DataFrame, optional
        Columns ``level``, ``size``: vertical lines at the hierarchy's sizes.
    """
    ax = _axes(ax, (7.0, 4.0))
    orders = list(dict.fromkeys(df["order"]))
    colours = mapping_colours(orders)
    line_sizes = sorted(set(int(s) for s in df["line_size"]), reverse=True)
    styles = ["-", "--", ":", "-."]
    for order in orders:
        for index, line_size in enumerate(line_sizes):
            rows = df[(df["order"] == order) & (df["line_size"] == line_size)]
            if rows.empty:
                continue
            ax.plot(rows["size"], rows["miss_ratio"], styles[index % len(styles)], color=colours[order],
                    marker=".", markersize=3, label=f"{order}, {line_size} B lines")
    ax.set_xscale("log", base=2)
    ax.set_yscale("log")
    ax.set_xlabel("cache size (bytes, fully associative LRU)")
    ax.set_ylabel("miss ratio")
    _mark_caches(ax, caches, "x")
    ax.legend(fontsize=7, frameon=False)
    return ax


def plot_cost_map(image, ax=None, *, label="compute cycles per pixel"):
    """A per-pixel cost image (H, W) with a colour bar."""
    ax = _axes(ax, (4.6, 4.0))
    shown = ax.imshow(np.asarray(image), cmap="magma", interpolation="nearest")
    ax.figure.colorbar(shown, ax=ax, label=label, shrink=0.85)
    ax.set_xticks([])
    ax.set_yticks([])
    return ax


def plot_miss_map(misses, level, ax=None, *, log=True):
    """One cache level of a per-pixel miss map, as an image with a colour bar.

    Parameters
    ----------
    misses : coherence.missmap.MissMap
        Misses per pixel per level of one run (:func:`coherence.miss_map`).
    level : str
        The level to draw (one of ``misses.levels``).
    ax : matplotlib Axes, optional
    log : bool
        Colours linear from 0 to 1 miss and logarithmic above (the lower
        levels' misses are few per pixel with rare large counts, which a
        linear scale shows as an empty image); False: linear throughout.

    Returns
    -------
    matplotlib Axes
        The image upright as rendered (row 0 at the top), titled with the
        scene, mapping, process count and level. An image larger than its
        axes is shown filtered (averaged), not sampled, so single pixels
        with many misses are not lost.
    """
    from matplotlib.colors import Normalize, SymLogNorm

    ax = _axes(ax, (4.6, 4.0))
    image = misses.level(level)
    top = max(1, int(image.max(initial=0)))
    norm = SymLogNorm(linthresh=1.0, linscale=0.5, vmin=0, vmax=top, base=10) if log else Normalize(0, top)
    shown = ax.imshow(image, origin="upper", cmap="viridis", norm=norm, interpolation="antialiased",
                      interpolation_stage="data")
    ax.figure.colorbar(shown, ax=ax, label="misses per pixel", shrink=0.85)
    ax.set_xticks([])
    ax.set_yticks([])
    ax.set_title(f"{misses.scene}, {misses.mapping} at {misses.n_processes} processes: {level}", fontsize=9)
    return ax


def plot_process_times(df, ax=None, *, order=None, parts=("compute_cycles", "memory_cycles", "dispatch_cycles")):
    """Stacked bars of each process's user time, grouped by mapping.

    Parameters
    ----------
    df : DataFrame
        Columns ``mapping``, ``process`` and the ``parts`` (cycles); one row
        per process of one process count.
    parts : sequence of str
        Columns stacked bottom to top (their sum is the user time).
    """
    ax = _axes(ax, (8.0, 3.6))
    names = _names(df, "mapping", order)
    shades = {"compute_cycles": "tab:blue", "memory_cycles": "tab:orange", "dispatch_cycles": "tab:gray"}
    position = 0.0
    ticks = []
    labelled = set()
    for name in names:
        rows = df[df["mapping"] == name].sort_values("process")
        x = position + np.arange(len(rows))
        bottom = np.zeros(len(rows))
        for part in parts:
            values = rows[part].to_numpy(dtype=np.float64)
            label = part.replace("_cycles", "") if part not in labelled else None
            labelled.add(part)
            ax.bar(x, values, 0.85, bottom=bottom, color=shades.get(part), label=label)
            bottom += values
        ticks.append((position + (len(rows) - 1) / 2, name))
        position += len(rows) + 1.5
    ax.set_xticks([t for t, _ in ticks], [n for _, n in ticks])
    ax.set_ylabel("user time per process (cycles)")
    ax.legend(fontsize=8, frameon=False)
    return ax


def plot_speedup(df, ax=None, *, column="speedup_user", order=None, n_cpus=None, title=None, legend=True):
    """Speed-up against the number of processes, one line per mapping, with the ideal line.

    The one speed-up plot of the package: the report draws one panel, the
    paper one per scene (:func:`plot_speedup_panels`).

    Parameters
    ----------
    df : DataFrame
        Columns ``mapping``, ``n_processes`` and ``column``.
    ax : matplotlib Axes, optional
        Where to draw; a new figure's axes if None.
    column : str
        The speed-up to draw, e.g. ``speedup_user`` or ``speedup_real``.
    order : sequence of str, optional
        Mapping order (colours and markers).
    n_cpus : int, optional
        Marks where processes start sharing CPUs with a dotted line.
    title : str, optional
    legend : bool
        Draw the legend on these axes.

    Returns
    -------
    matplotlib Axes
    """
    from matplotlib.ticker import MaxNLocator

    ax = _axes(ax, (5.0, 4.0))
    names = _names(df, "mapping", order)
    colours = mapping_colours(names)
    markers = ["o", "s", "^", "D", "v", "P", "X", "*"]
    top = int(df["n_processes"].max())
    ax.plot([1, top], [1, top], color="0.6", linewidth=1, linestyle="--", label="ideal")
    for index, name in enumerate(names):
        rows = df[df["mapping"] == name].sort_values("n_processes")
        ax.plot(rows["n_processes"], rows[column], marker=markers[index % len(markers)], markersize=3.5,
                linewidth=1.2, color=colours[name], label=name)
    if n_cpus is not None and n_cpus < top:
        ax.axvline(n_cpus, color="0.35", linestyle=":", linewidth=1)
        ax.annotate(f"{n_cpus} CPUs", xy=(n_cpus, 1.0), xycoords=("data", "axes fraction"), xytext=(2, -10),
                    textcoords="offset points", fontsize=8, color="0.25")
    ax.set_xlim(0.5, top + 0.5)
    ax.set_ylim(0, top + 0.5)
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.yaxis.set_major_locator(MaxNLocator(integer=True))
    ax.grid(True, color="0.92", linewidth=0.6)
    ax.set_xlabel("processes")
    ax.set_ylabel(column.replace("_", " "))
    if title:
        ax.set_title(title, fontsize=10)
    if legend:
        ax.legend(fontsize=8, frameon=False)
    return ax


def plot_speedup_panels(df, *, column="speedup_real", order=None, n_cpus=None, title=None, by="scene"):
    """One :func:`plot_speedup` panel per value of ``by`` (the study's figure style), on a new figure.

    Parameters
    ----------
    df : DataFrame
        Columns ``by``, ``mapping``, ``n_processes`` and ``column``.
    column, order, n_cpus :
        As for :func:`plot_speedup`.
    title : str, optional
        The figure's title.
    by : str
        Column whose values get a panel each, in order of appearance.

    Returns
    -------
    matplotlib.figure.Figure
        Up to three panels a row; a spare panel, if any, holds the legend.
    """
    from matplotlib.figure import Figure

    panels = list(dict.fromkeys(df[by]))
    ncols = min(3, len(panels))
    nrows = -(-len(panels) // ncols)
    fig = Figure(figsize=(4.0 * ncols, 3.5 * nrows + 0.4))
    axes = fig.subplots(nrows, ncols, squeeze=False).ravel()
    spare = axes[len(panels)] if len(panels) < len(axes) else None
    for index, (ax, panel) in enumerate(zip(axes, panels)):
        plot_speedup(df[df[by] == panel], ax, column=column, order=order, n_cpus=n_cpus,
                     title=str(panel).capitalize(), legend=spare is None and index == 0)
    for ax in axes[len(panels):]:
        ax.set_axis_off()
    if spare is not None:
        spare.legend(*axes[0].get_legend_handles_labels(), loc="center", frameon=False, fontsize=10)
    if title:
        fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    return fig
