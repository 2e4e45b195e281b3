"""What a what-if study writes: its long-form CSV, a figure, and the exact LRU curves, as one unit.

Each CSV has a ``.meta.json`` beside it (:func:`coherence.provenance.provenance`)
that records the study's name, its base choices (``experiment``:
:meth:`analyses.experiment.Experiment.as_parameters`) and its grid.
"""
from __future__ import annotations

from pathlib import Path

import pandas as pd

__all__ = ["save_whatif", "lru_csv_path", "WHATIF_FILES", "whatif_files"]

#: The files :func:`save_whatif` writes for a study called ``{name}``, by what they hold: the
#: long-form table, its figure and (for grids over level sizes) the exact LRU curves; each CSV
#: has its sidecar (:func:`coherence.provenance.meta_path`) beside it.
WHATIF_FILES = {"table": "whatif-{name}.csv", "figure": "whatif-{name}.png", "lru": "whatif-{name}-lru.csv"}


def whatif_files(name: str) -> dict[str, str]:
    """:data:`WHATIF_FILES` for the study called ``name``."""
    return {role: pattern.format(name=name) for role, pattern in WHATIF_FILES.items()}


def save_whatif(table: pd.DataFrame, study, folder, curves: pd.DataFrame | None = None) -> tuple[Path, Path]:
    """Write ``whatif-<name>.csv`` (long form, with .meta.json), a figure and, given ``curves``,
    ``whatif-<name>-lru.csv`` (with .meta.json), all as one unit.

    Every file's bytes are made first (the figure too) and then renamed into
    place together (:func:`rtcommon.files.write_files_atomic`), so an
    interrupted run leaves the previous set or the new one, never a new CSV
    beside an old figure; temporary names are unique, so concurrent runs into
    one folder do not collide.
    """
    from matplotlib.figure import Figure

    from analyses.html import figure_png
    from analyses.maps import plot_loss_lines, plot_loss_map, plot_texel_misses
    from analyses.whatif import long_form
    from coherence.provenance import provenance
    from rtcommon.files import write_files_atomic

    folder = Path(folder)
    csv = folder / whatif_files(study.name)["table"]
    files = _table_files(long_form(table, study), csv,
                         provenance(study=study.name, scene=study.scene, size=study.size,
                                    mappings=list(study.mappings), n_processes=study.n_processes,
                                    hierarchy=study.hierarchy, cost=study.cost, layout=study.layout,
                                    n_cpus=study.n_cpus, background=study.background,
                                    experiment=study.experiment.as_parameters(),
                                    grid={key: [str(v) for v in values] for key, values in study.grid.items()}))
    keys = list(study.grid)
    if "texture_layout" in keys and "texel_L1_misses_per_access" in table.columns:
        others = [key for key in keys if key != "texture_layout"]
        panels = list(dict.fromkeys(table[others[0]])) if others else [None]
        figure = Figure(figsize=(5.5 * len(panels), 4.2))
        axes = figure.subplots(1, len(panels), squeeze=False)
        for ax, value in zip(axes[0], panels):
            rows = table if value is None else table[table[others[0]] == value]
            if len(others) > 1:
                rows = rows[(rows[others[1:]] == rows[others[1:]].iloc[0]).all(axis=1)]
            plot_texel_misses(rows, ax=ax)
            if value is not None:
                ax.set_title(f"{others[0]} = {value}", fontsize=10)
    elif len(keys) >= 2:
        mappings = list(dict.fromkeys(table["mapping"]))
        figure = Figure(figsize=(5.5 * len(mappings), 4.5))
        axes = figure.subplots(1, len(mappings), squeeze=False)
        rest = keys[2:]
        rows = table if not rest else table[(table[rest] == table[rest].iloc[0]).all(axis=1)]
        for ax, mapping in zip(axes[0], mappings):
            plot_loss_map(rows, keys[0], keys[1], mapping, ax=ax)
    else:
        figure = Figure(figsize=(7, 4.5))
        plot_loss_lines(table, keys[0], ax=figure.subplots())
    png = folder / whatif_files(study.name)["figure"]
    files[png] = figure_png(figure, dpi=100)
    if curves is not None:
        files.update(_table_files(curves, lru_csv_path(study, folder),
                                  provenance(study=study.name, scene=study.scene, size=study.size,
                                             layout=study.layout, n_processes=study.n_processes,
                                             experiment=study.experiment.as_parameters(),
                                             note="fully associative LRU, exact from reuse distances")))
    write_files_atomic(files)
    return csv, png


def lru_csv_path(study, folder) -> Path:
    """Where :func:`save_whatif` writes the exact LRU curves."""
    return Path(folder) / whatif_files(study.name)["lru"]


def _table_files(table: pd.DataFrame, path: Path, meta: dict) -> dict:
    # the same bytes as coherence.provenance.write_csv_atomic writes, to be written with the other files
    import json

    from coherence.provenance import meta_path

    return {path: table.to_csv(index=False, lineterminator="\n"), meta_path(path): json.dumps(meta, indent=2) + "\n"}
