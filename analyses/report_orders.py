"""The report's ray-order section, for path-traced traces: when does the order of rays matter?

Every process owns rays by the pixel mapping, then traces them in a ray order
of :data:`coherence.ray_orders.RAY_ORDERS` (:mod:`coherence.ordered_runs`:
static mappings order each process's rays together, DB the rays of each
handed-out block). For every compared mapping and order at the section's
process count, one table row holds misses per ray by cache level, the
modelled time, and the efficiency split into five factors whose product is
the efficiency (speed-up over ``n``), with ``T1`` and ``D1`` the mapping's
one-process user and dispatch cycles (depth-first), ``W0`` the run's work
without dispatch, ``W0_df`` the same for the depth-first order and ``W0'``
for the order without its own costs (its buffer and queue records and its
sorting cycles left out; a second run, since the order's buffer lines share
the caches with the scene's and evict some of them, so the scene's misses
without the buffers are not the ordered run's scene misses):

* ``load_balance`` = ``W / (n max u)``, as the study's;
* ``coherence_factor`` = ``(T1 - D1) / W0_df``: the mapping's, as the study's;
* ``reordering_gain`` = ``W0_df / W0'``: above 1 when the order made the
  caches work less;
* ``reordering_overhead`` = ``W0' / W0``: below 1 by what the order's own
  memory traffic and sorting cost;
* ``dispatch_factor`` = ``(W0 / W) / ((T1 - D1) / T1)``, as the study's.

The depth-first order is the study's run itself (gain and overhead 1).
The registered treelet order runs with treelets of the hierarchy's first
level's size and nodes of the placed layout's kd-node size; column
``treelet_bytes`` says the treelet size an order used (0: not a treelet order).
Under a platform every order runs on its shared levels, as the study's runs
(:func:`coherence.ordered_runs.simulate_ordered_shared`), treelets sized to its
whole first level.
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from tracer.trace.records import AuxKind, unpack_aux

#: The section's columns besides mapping, order and the per-level misses per ray.
ORDER_COLUMNS = ("n_processes", "rays", "user_seconds_max", "real_seconds", "speedup_user", "efficiency",
                 "load_balance", "coherence_factor", "reordering_gain", "reordering_overhead", "dispatch_factor",
                 "ray_state_records", "queue_records", "sort_cycles", "treelet_bytes")


def registry_orders(order, *, scene_bounds, tree=None, records=None) -> tuple:
    """Two :data:`coherence.ordered_runs.Order` of an order of :data:`coherence.ray_orders.RAY_ORDERS`: the
    order itself, and the same without its own costs (its buffer and queue records and its sorting cycles
    left out: the ``W0'`` run of the module docstring). The second reuses the piece ranges of every unit the
    first ordered (held as long as the pair is; only the ranges). ``tree`` (a KdTree) and ``records`` (the trace's) go to orders that need
    them (treelet queues)."""
    from coherence.ordered_runs import OrderedUnit, pieces_unit
    from coherence.ray_orders import get_ray_order, order_pieces

    order = get_ray_order(order)
    extra = {"records": records} if getattr(order, "needs_records", False) else {}

    made = {}  # each ordered unit's piece ranges only: all the bare order reads

    def pieces_of(segments, rows):
        pieces = order_pieces(segments, rows, order, scene_bounds=scene_bounds, tree=tree, **extra)
        made[rows.tobytes()] = (pieces.piece_first, pieces.piece_stop)
        return pieces

    def ordered(segments, rows, n_records):
        return pieces_unit(pieces_of(segments, rows), n_records)

    def bare(segments, rows, n_records):
        key = rows.tobytes()
        first, stop = made[key] if key in made else pieces_of(segments, rows)[:2]
        return OrderedUnit(first, stop, np.zeros(0, np.uint32), 0.0)

    return ordered, bare


def order_section(trace, study_runs: pd.DataFrame, setup: dict, n_processes: int, orders=None) -> pd.DataFrame:
    """The section's table (module docstring), one row per (mapping, order).

    Parameters
    ----------
    trace : tracer.trace.access.AccessTrace
        Path-traced (with segments).
    study_runs : DataFrame
        The study's runs of the same mappings, at 1 and ``n_processes``
        (:func:`coherence.studies.study`).
    setup : dict
        ``mappings`` (Mapping objects), ``hierarchy``, ``placed``, ``cost``,
        ``machine`` and, for orders that need the kd-tree, ``tree`` or the
        ``scene`` to build it from with the trace's recorded ``kd_config``.
        ``hierarchy`` is that of ``study_runs``: a :class:`cachesim.Hierarchy`
        (private caches, :func:`coherence.ordered_runs.simulate_ordered`) or a
        platform's :class:`coherence.shared_run.SharedLevels`, on which every
        order runs (:func:`coherence.ordered_runs.simulate_ordered_shared`),
        treelets sized to its first level's whole size.
    n_processes : int
    orders : sequence of str or RayOrder, optional
        Default :func:`report_orders`.

    Returns
    -------
    DataFrame
        Columns mapping, order, ``<level>_misses_per_ray`` per level, then :data:`ORDER_COLUMNS`.
    """
    from coherence.ray_orders import get_ray_order, scene_bounds_of
    from coherence.shared_run import SharedLevels

    if isinstance(setup["hierarchy"], SharedLevels):  # the orders' runs on shared levels too
        setup = {**setup, "shared": setup["hierarchy"], "hierarchy": setup["hierarchy"].hierarchy}
    levels = [level.name for level in setup["hierarchy"].levels]
    bounds = scene_bounds_of(trace.segments)
    chosen = ([_sized(get_ray_order(order), setup) for order in orders] if orders is not None
              else report_orders(setup))
    if setup.get("tree") is None and any(order.needs_tree for order in chosen):
        setup = {**setup, "tree": _trace_tree(trace, setup["scene"])}
    rows = []
    for mapping in setup["mappings"]:
        mine = study_runs[study_runs["mapping"] == mapping.name].set_index("n_processes")
        one, depth_first = mine.loc[1], mine.loc[n_processes]
        t1, d1 = float(one["user_cycles_max"]), float(one["dispatch_cycles"])
        w0_df = float(depth_first["work_cycles_without_dispatch"])
        distribution = mapping.build(trace.width, trace.height, n_processes)
        for order in chosen:
            name = order.name
            if name == "depth-first":  # the study's run itself
                summary, aux, sort_cycles, w0_bare = depth_first, np.zeros(0, np.uint32), 0.0, w0_df
            else:
                summary, aux, sort_cycles, w0_bare = _ordered_run(trace, distribution, order, setup, bounds)
            w = float(summary["work_cycles"])
            w0 = float(summary["work_cycles_without_dispatch"])
            aux_kind = unpack_aux(aux)[0]
            row = {"mapping": mapping.name, "order": name}
            row.update({f"{level}_misses_per_ray": float(summary[f"{level}_misses_per_ray"]) for level in levels})
            row.update({
                "n_processes": n_processes, "rays": int(summary["rays"]),
                "user_seconds_max": float(summary["user_seconds_max"]), "real_seconds": float(summary["real_seconds"]),
                "speedup_user": t1 / float(summary["user_cycles_max"]),
                "efficiency": t1 / float(summary["user_cycles_max"]) / n_processes,
                "load_balance": float(summary["load_balance"]),
                "coherence_factor": (t1 - d1) / w0_df,
                "reordering_gain": w0_df / w0_bare,
                "reordering_overhead": w0_bare / w0,
                "dispatch_factor": (w0 / w) / ((t1 - d1) / t1),
                "ray_state_records": int(np.count_nonzero(aux_kind == AuxKind.RAY_STATE)),
                "queue_records": int(np.count_nonzero(aux_kind == AuxKind.QUEUE_ENTRY)),
                "sort_cycles": float(sort_cycles),
                "treelet_bytes": int(getattr(order, "treelet_bytes", 0)),
            })
            rows.append(row)
    return pd.DataFrame(rows)


def report_orders(setup: dict) -> list:
    """Every order of :data:`coherence.ray_orders.RAY_ORDERS`, the registered treelet queues sized to the
    section: treelets of the first cache level's size, nodes of the placed layout's kd-node size."""
    from coherence.ray_orders import RAY_ORDERS

    return [_sized(order, setup) for order in RAY_ORDERS.values()]


def _sized(order, setup: dict):
    """``order``, or if it is the registered ``treelet`` order, that order with treelets of ``setup``'s first
    cache level's size (at least one node) and nodes of the placed layout's kd-node size; other orders, and
    treelet orders with sizes of their own, are kept."""
    from coherence.ray_orders import RAY_ORDERS
    from tracer.trace.records import RecordKind

    if order != RAY_ORDERS["treelet"]:
        return order
    placed = setup["placed"]
    node_bytes = int(placed.record_size[placed.kind_first[RecordKind.KD_NODE]])
    return order.sized(int(setup["hierarchy"].levels[0].size), node_bytes)


def _trace_tree(trace, scene):
    """The kd-tree the trace was rendered with, built again from ``scene`` and the trace's ``kd_config``."""
    from tracer.kd.tree import KdTreeConfig, build_kdtree

    return build_kdtree(scene, KdTreeConfig(**trace.metadata["kd_config"]))


def order_rows(table: pd.DataFrame, rounded) -> list:
    """``results.csv``'s ``ray_orders`` rows of the section's ``table``: (section, mapping, n_processes, item =
    order, metric, ``rounded(value)``)."""
    rows = []
    for record in table.to_dict(orient="records"):
        for metric, value in record.items():
            if metric not in ("mapping", "order", "n_processes"):
                rows.append(("ray_orders", record["mapping"], int(record["n_processes"]), record["order"], metric,
                             rounded(value)))
    return rows


def order_table_html(table: pd.DataFrame) -> pd.DataFrame:
    """The section's table as the page shows it: one row per order, fewer and shorter columns."""
    shown = table.drop(columns=["n_processes", "rays", "real_seconds"]).copy()
    shown.columns = [c.replace("_misses_per_ray", " misses/ray").replace("_", " ") for c in shown.columns]
    return shown


def _ordered_run(trace, distribution, order, setup: dict, bounds) -> tuple:
    """One order's run: its summary (:func:`coherence.metrics.run_summary`), aux records, sorting cycles, and
    the work without dispatch of the same order without its own costs."""
    from coherence.metrics import run_summary
    from coherence.ordered_runs import simulate_ordered, simulate_ordered_shared
    from coherence.ray_order_base import OrderBuffers

    hierarchy, placed, cost, machine = (setup[key] for key in ("hierarchy", "placed", "cost", "machine"))
    shared = setup.get("shared")
    name = order.name
    ordered, bare = registry_orders(order, scene_bounds=bounds, tree=setup.get("tree"), records=trace.records)

    def simulated(chosen):
        if shared is None:
            return simulate_ordered(trace, distribution, chosen, hierarchy, placed, cost, machine, name=name,
                                    extents=OrderBuffers().extents)
        run, work = simulate_ordered_shared(trace, distribution, chosen, shared, placed, cost, machine, name=name)
        return run.run, work

    run, work = simulated(ordered)
    summary = run_summary(run.processes, [level.name for level in hierarchy.levels], cost.clock_hz, run.real_cycles)
    w0_bare = summary["work_cycles_without_dispatch"]
    aux, sort_cycles = np.array(work.trace.records[trace.n_records:]), work.sort_cycles
    del run, work  # the ordered run's pieces, records and per-piece counters, before the bare run makes its own
    if len(aux) or sort_cycles:
        plain, _ = simulated(bare)
        w0_bare = float((plain.processes["user_cycles"] - plain.processes["dispatch_cycles"]).sum())
    return summary, aux, sort_cycles, w0_bare
