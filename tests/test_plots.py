"""Plot functions: draw what the table says, return the axes, and leave the table alone."""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
import pytest  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from analyses import plots  # noqa: E402

CACHES = pd.DataFrame({"level": ["L1", "L2", "L3"], "size": [8192, 98304, 4 << 20]})


@pytest.fixture(autouse=True)
def _close():
    yield
    plt.close("all")


def _runs():
    rows = []
    for mapping, slope in (("S", 0.7), ("P", 1.0), ("DB", 0.95)):
        for n in (1, 2, 4, 8):
            rows.append({"mapping": mapping, "n_processes": n, "speedup_user": 1 + slope * (n - 1),
                         "speedup_real": 1 + 0.5 * slope * (n - 1)})
    return pd.DataFrame(rows)


def _check_unchanged(function, frame, **kwargs):
    before = frame.copy(deep=True)
    ax = function(frame, Figure().subplots(), **kwargs)
    pd.testing.assert_frame_equal(frame, before)
    return ax


def test_speedup_lines_per_mapping_and_ideal():
    runs = _runs()
    ax = _check_unchanged(plots.plot_speedup, runs, column="speedup_user", order=["P", "S", "DB"], n_cpus=4)
    labels = [line.get_label() for line in ax.get_lines() if not line.get_label().startswith("_")]
    assert labels == ["ideal", "P", "S", "DB"]
    s_line = [line for line in ax.get_lines() if line.get_label() == "S"][0]
    assert np.allclose(s_line.get_ydata(), runs[runs["mapping"] == "S"]["speedup_user"])
    assert ax.get_xlabel() == "processes"


def test_speedup_creates_axes_when_none_given():
    """Without ``ax`` the plot draws on a new pyplot figure exactly what it draws on given axes.
    Fails when ``_axes`` returns a fresh ``Figure().subplots()`` (not pyplot's: a notebook shows
    nothing) or when the drawing depends on where it goes."""
    runs = _runs()
    ax = plots.plot_speedup(runs, column="speedup_real")
    assert ax.figure in [plt.figure(number) for number in plt.get_fignums()]
    given = plots.plot_speedup(runs, Figure().subplots(), column="speedup_real")
    drawn = [(line.get_label(), list(line.get_xdata()), list(line.get_ydata())) for line in ax.get_lines()]
    assert drawn == [(line.get_label(), list(line.get_xdata()), list(line.get_ydata())) for line in given.get_lines()]
    db = [line for line in ax.get_lines() if line.get_label() == "DB"][0]
    assert np.allclose(db.get_ydata(), runs[runs["mapping"] == "DB"]["speedup_real"])


def test_speedup_panels_one_per_scene_with_the_legend_in_the_spare_panel():
    scenes = ("balls", "tetra", "shell", "room")  # four panels on a 3x2 grid leave two spare
    runs = pd.concat([_runs().assign(scene=scene) for scene in scenes], ignore_index=True)
    before = runs.copy(deep=True)
    fig = plots.plot_speedup_panels(runs, column="speedup_user", order=["DB", "S", "P"], n_cpus=4, title="t")
    pd.testing.assert_frame_equal(runs, before)
    drawn = [ax for ax in fig.axes if ax.get_lines()]
    assert [ax.get_title() for ax in drawn] == [scene.capitalize() for scene in scenes]
    spare = [ax for ax in fig.axes if ax.get_legend() is not None]
    assert len(spare) == 1 and not spare[0].get_lines()
    assert [text.get_text() for text in spare[0].get_legend().get_texts()] == ["ideal", "DB", "S", "P"]


def test_figure_png_is_a_png_without_software_entry():
    from analyses.html import figure_png, png_base64

    fig = Figure(figsize=(1, 1))
    fig.subplots().plot([0, 1], [0, 1])
    data = figure_png(fig)
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and b"matplotlib" not in data
    assert png_base64(data) == png_base64(figure_png(fig))


def test_level_metric_bar_per_mapping_count_and_level():
    rows = [{"mapping": m, "n_processes": n, "level": lv, "misses_per_ray": 0.1 * (i + 1)}
            for m in ("S", "P") for n in (1, 8) for i, lv in enumerate(("L1", "L2", "L3"))]
    ax = _check_unchanged(plots.plot_level_metric, pd.DataFrame(rows))
    assert len(ax.patches) == 2 * 2 * 3
    assert [t.get_text() for t in ax.get_xticklabels()] == ["L1", "L2", "L3"]
    assert ax.get_yscale() == "log"


def test_miss_ratio_curves_and_cache_marks():
    sizes = 64 * 2 ** np.arange(8)
    curves = pd.concat([pd.DataFrame({"order": order, "line_size": line, "size": sizes,
                                      "miss_ratio": np.linspace(0.9, 0.01, sizes.size)})
                        for order in ("scan (S P R)", "B order (B)") for line in (32, 64)], ignore_index=True)
    ax = _check_unchanged(plots.plot_miss_ratio_curves, curves, caches=CACHES)
    curve_lines = [line for line in ax.get_lines() if "lines" in line.get_label()]
    assert len(curve_lines) == 4
    marks = [line for line in ax.get_lines() if line.get_linestyle() == ":"]
    assert sorted(line.get_xdata()[0] for line in marks) == [8192, 98304, 4 << 20]


def test_process_times_stack_parts():
    frame = pd.DataFrame({"mapping": ["S"] * 3 + ["P"] * 3, "process": [0, 1, 2] * 2,
                          "compute_cycles": [1.0, 2.0, 3.0, 2.0, 2.0, 2.0],
                          "memory_cycles": [0.1] * 6, "dispatch_cycles": [0.0] * 6})
    ax = _check_unchanged(plots.plot_process_times, frame)
    assert len(ax.patches) == 6 * 3
    tops = sorted(p.get_y() + p.get_height() for p in ax.patches)
    assert tops[-1] == pytest.approx(3.1)


def test_scene_bytes_and_cost_map_and_image():
    frame = pd.DataFrame({"kind": ["kd_node", "sphere", "total"], "bytes": [1000, 3000, 4000]})
    ax = _check_unchanged(plots.plot_scene_bytes, frame, caches=CACHES)
    assert [p.get_width() for p in ax.patches] == [1000, 3000, 4000]
    cost = np.arange(12.0).reshape(3, 4)
    ax = plots.plot_cost_map(cost, Figure().subplots())
    assert np.array_equal(ax.get_images()[0].get_array(), cost)
    ax = plots.plot_image(np.full((2, 2, 3), 2.0), Figure().subplots(), title="x")
    assert ax.get_images()[0].get_array().max() == 1.0


def test_mapping_colours_are_stable():
    colours = plots.mapping_colours(["S", "P", "R"])
    assert colours["S"] != colours["P"] and plots.mapping_colours(["S"])["S"] == colours["S"]


def test_pages_escape_data_but_not_tables():
    from analyses.html import _environment, table_html

    template = _environment().from_string("{{ name }} {{ frame|table }}")
    page = template.render(name="<b>", frame=pd.DataFrame({"a&b": ["<i>"]}))
    assert page.startswith("&lt;b&gt; <div class=\"wide\"><table>")
    assert "<th>a&amp;b</th>" in page and "<td>&lt;i&gt;</td>" in page
    assert str(table_html(pd.DataFrame({"x": [1234]}))).count("1,234") == 1
