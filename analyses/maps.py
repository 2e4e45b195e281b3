"""Figures of what-if results: where coherence loss overtakes imbalance loss."""
from __future__ import annotations

import numpy as np

from analyses.plots import _axes


def plot_loss_map(df, x: str, y: str, mapping: str, ax=None):
    """Map of ``coherence_loss - imbalance_loss`` over two grid parameters.

    Parameters
    ----------
    df : DataFrame
        Rows of :func:`analyses.whatif.run_whatif` with columns ``x``, ``y``,
        ``mapping``, ``coherence_loss`` and ``imbalance_loss``.
    x, y : str
        Grid parameters on the axes (shown in grid order, evenly spaced).
    mapping : str
        Which mapping's rows to draw.
    ax : matplotlib Axes, optional

    Returns
    -------
    matplotlib Axes
        Red cells: coherence lost more than balance; blue: balance lost more.
    """
    ax = _axes(ax, (6, 4.5))
    rows = df[df["mapping"] == mapping]
    table = rows.assign(difference=rows["coherence_loss"] - rows["imbalance_loss"]) \
        .pivot_table(index=y, columns=x, values="difference", sort=False)
    limit = float(np.nanmax(np.abs(table.to_numpy()))) or 1.0
    image = ax.imshow(table.to_numpy(), origin="lower", cmap="coolwarm", vmin=-limit, vmax=limit, aspect="auto")
    ax.set_xticks(range(table.shape[1]), [str(value) for value in table.columns])
    ax.set_yticks(range(table.shape[0]), [str(value) for value in table.index])
    ax.set_xlabel(x)
    ax.set_ylabel(y)
    for (row, column), value in np.ndenumerate(table.to_numpy()):
        ax.text(column, row, "C" if value > 0 else "B", ha="center", va="center", fontsize=8)
    ax.set_title(f"{mapping}  (C: coherence decides, B: balance)", fontsize=10)
    ax.figure.colorbar(image, ax=ax, label="coherence loss - imbalance loss")
    return ax


def plot_loss_lines(df, x: str, mapping_column: str = "mapping", ax=None):
    """Imbalance and coherence loss against one grid parameter, per mapping.

    ``df`` holds rows of :func:`analyses.whatif.run_whatif` for a one-parameter
    grid ``x``.
    """
    ax = _axes(ax, (6, 4))
    positions = {value: index for index, value in enumerate(dict.fromkeys(df[x]))}
    for mapping, rows in df.groupby(mapping_column, sort=False):
        line, = ax.plot([positions[v] for v in rows[x]], rows["imbalance_loss"], marker="o", label=f"{mapping} imbalance")
        ax.plot([positions[v] for v in rows[x]], rows["coherence_loss"], marker="s", linestyle="--",
                color=line.get_color(), label=f"{mapping} coherence")
    ax.set_xticks(list(positions.values()), [str(value) for value in positions])
    ax.set_xlabel(x)
    ax.set_ylabel("efficiency lost")
    ax.legend(fontsize=7, ncol=2)
    return ax


def plot_texel_misses(df, level: str = "L1", x: str = "texture_layout", ax=None):
    """Texel misses per texel read at one cache level, against the texel order, per mapping.

    ``df`` holds rows of :func:`analyses.whatif.run_whatif` on a textured
    scene (columns ``x``, ``mapping`` and ``texel_<level>_misses_per_access``),
    for one value of every other grid parameter.
    """
    ax = _axes(ax, (6, 4))
    column = f"texel_{level}_misses_per_access"
    positions = {value: index for index, value in enumerate(dict.fromkeys(df[x]))}
    mappings = list(dict.fromkeys(df["mapping"]))
    width = 0.8 / max(1, len(mappings))
    for k, mapping in enumerate(mappings):
        rows = df[df["mapping"] == mapping]
        ax.bar([positions[v] - 0.4 + (k + 0.5) * width for v in rows[x]], rows[column], width, label=mapping)
    ax.set_xticks(list(positions.values()), [str(value) for value in positions])
    ax.set_xlabel(x)
    ax.set_ylabel(f"{level} misses per texel read")
    ax.legend(fontsize=7, ncol=3)
    return ax
