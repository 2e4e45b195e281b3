"""The crossover study: where a fine mapping's coherence loss meets S's imbalance loss."""
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from analyses.crossover import _first_crossing, crossover_boundary, crossover_study, plot_crossover
from coherence.layout import MemoryLayout, RecordLayout, get_layout
from coherence.studies import study
from trace_factory import SMALL, random_trace


def test_first_crossing_by_hand():
    scales = np.array([1.0, 4.0, 16.0])
    assert _first_crossing(scales, np.array([-0.1, 0.1, 0.2])) == pytest.approx(2.0)  # halfway in log m
    assert _first_crossing(scales, np.array([-0.3, -0.1, 0.1])) == pytest.approx(8.0)
    assert _first_crossing(scales, np.array([0.0, 0.1, 0.2])) == 1.0
    assert np.isnan(_first_crossing(scales, np.array([-0.3, -0.2, -0.1])))


def test_scaled_layout_multiplies_every_size_and_keeps_alignment():
    base = get_layout("alpha1997")
    scaled = base.scaled(3)
    for name, record in base.records.items():
        assert scaled.records[name] == RecordLayout(record.size * 3, record.align, record.per_vertex * 3)
    assert base.scaled(1) == base
    with pytest.raises(ValueError, match="factor"):
        base.scaled(0)


def test_each_point_is_the_study_at_that_layout_and_latency():
    trace = random_trace(16, 12, seed=3)
    table = crossover_study(trace, cost="alpha8400", hierarchy=SMALL, n_processes=4, record_scales=[1, 2],
                            latency_scales=[1, 8])
    assert len(table) == 2 * 2 * 3
    # the point (2, 8) by hand: every record twice as big, memory 8 times slower
    compact = get_layout("compact")
    doubled = MemoryLayout(records={name: RecordLayout(2 * r.size, r.align, 2 * r.per_vertex)
                                    for name, r in compact.records.items()}, base=compact.base,
                           region_align=compact.region_align)
    slower = replace(SMALL, memory_latency=8 * SMALL.memory_latency)
    direct = study(trace, ["S", "P", "R"], [4], hierarchy=slower, layout=doubled, cost="alpha8400",
                   progress=False).runs.set_index(["mapping", "n_processes"])
    point = table[(table["record_scale"] == 2) & (table["latency_scale"] == 8)].set_index("mapping")
    for mapping in ("S", "P", "R"):
        for column in ("imbalance_loss", "coherence_loss", "speedup_user"):
            assert point.loc[mapping, column] == pytest.approx(direct.loc[(mapping, 4), column], rel=1e-12)
    assert (point["memory_latency"] == slower.memory_latency).all()


def test_boundary_from_a_table_by_hand():
    rows = []
    for k, s_loss, p_losses in ((1, 0.2, (0.0, 0.1, 0.3)), (4, 0.2, (0.25, 0.3, 0.4)), (16, 0.2, (0.0, 0.0, 0.1))):
        for m, p_loss in zip((1, 4, 16), p_losses):
            rows.append({"record_scale": k, "latency_scale": m, "mapping": "S", "imbalance_loss": s_loss,
                         "coherence_loss": 0.0})
            rows.append({"record_scale": k, "latency_scale": m, "mapping": "P", "imbalance_loss": 0.0,
                         "coherence_loss": p_loss})
    boundary = crossover_boundary(pd.DataFrame(rows)).set_index("record_scale")
    assert boundary.loc[1, "latency_scale"] == pytest.approx(np.exp(np.log(4) + 0.5 * np.log(4)))  # 8
    assert boundary.loc[4, "latency_scale"] == 1.0
    assert np.isnan(boundary.loc[16, "latency_scale"])
    assert boundary.loc[1, "gap_at_1"] == pytest.approx(-0.2)
    from matplotlib.figure import Figure

    ax = Figure().subplots()
    assert plot_crossover(boundary.reset_index(), ax=ax) is ax
    assert len(ax.lines) == 2  # P's boundary and the study's machine


@pytest.mark.parametrize("kwargs, message", [
    ({"record_scales": [2, 1]}, "record_scales"),
    ({"latency_scales": [0.5, 1]}, "latency_scales"),
    ({"n_processes": 1}, "n_processes"),
])
def test_bad_grids_are_refused(kwargs, message):
    with pytest.raises(ValueError, match=message):
        crossover_study(random_trace(), cost="alpha8400", hierarchy=SMALL, **kwargs)
