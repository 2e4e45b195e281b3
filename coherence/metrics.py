"""Speed-ups and the efficiency decomposition of simulated runs.

For a mapping run by ``n`` processes with user times ``u_p`` (including
dispatch waits ``d_p``), ``T1`` the user time of the same mapping on one
process (``D1`` of it dispatch), ``W = sum(u_p)`` and ``W0 = sum(u_p - d_p)``:

- user speed-up ``T1 / max(u_p)`` (the study's definition: the worst
  process decides), efficiency = speed-up / n;
- load-balance efficiency ``mean(u_p) / max(u_p) = W / (n max(u_p))``;
- coherence factor ``(T1 - D1) / W0``: below 1 when splitting the image
  made the processes' caches work harder in total than one process's did
  (above 1 when sharing a CPU warmed them);
- dispatch-overhead factor ``(W0 / W) / ((T1 - D1) / T1)``: the share of
  work lost to hand-outs, relative to one process's (1 for static mappings;
  near 1 for DB, whose one-process run pays every hand-out too; DB's
  hand-outs show against the best one-process time, ``speedup_user_vs_best``,
  and in ``dispatch_share = D / W``).

Efficiency = load balance x coherence x dispatch, exactly.
"""
from __future__ import annotations

import numpy as np
import pandas as pd
from rtcommon.validate import InputError

RAY_COUNTERS = ("primary_rays", "shadow_rays", "reflection_rays", "refraction_rays")

#: The factors whose product is the efficiency, in that order.
EFFICIENCY_FACTORS = ("load_balance", "coherence_factor", "dispatch_factor")
#: ``1 - factor`` for each of :data:`EFFICIENCY_FACTORS`: what imbalance, coherence and hand-outs cost.
LOSS_COLUMNS = ("imbalance_loss", "coherence_loss", "dispatch_loss")
#: The columns of the efficiency decomposition that :func:`add_speedups` adds
#: and the report, the paper and what-if studies show, in the order they show them.
DECOMPOSITION_COLUMNS = ("speedup_user", "speedup_real", "efficiency", *EFFICIENCY_FACTORS, *LOSS_COLUMNS)


def run_summary(processes: pd.DataFrame, level_names, clock_hz: float, real_cycles: float) -> dict:
    """Per-run figures that need no one-process reference (one dict row)."""
    user = processes["user_cycles"].to_numpy(dtype=np.float64)
    dispatch = processes["dispatch_cycles"].to_numpy(dtype=np.float64)
    rays = float(processes[[c for c in RAY_COUNTERS if c in processes]].to_numpy().sum())
    row = {
        "n_processes": int(len(processes)),
        "pixels": int(processes["pixels"].sum()),
        "rays": int(rays),
        "user_cycles_max": float(user.max()),
        "user_cycles_mean": float(user.mean()),
        "work_cycles": float(user.sum()),
        "work_cycles_without_dispatch": float((user - dispatch).sum()),
        "compute_cycles": float(processes["compute_cycles"].sum()),
        "memory_cycles": float(processes["memory_cycles"].sum()),
        "dispatch_cycles": float(dispatch.sum()),
        "real_cycles": float(real_cycles),
        "user_seconds_max": float(user.max()) / clock_hz,
        "real_seconds": float(real_cycles) / clock_hz,
        "load_balance": float(user.mean() / user.max()) if user.max() > 0 else 1.0,
    }
    for name in level_names:
        accesses = int(processes[f"{name}_accesses"].sum())
        hits = int(processes[f"{name}_hits"].sum())
        misses = int(processes[f"{name}_misses"].sum())
        row[f"{name}_accesses"] = accesses
        row[f"{name}_hit_rate"] = hits / accesses if accesses else float("nan")
        row[f"{name}_misses_per_ray"] = misses / rays if rays else float("nan")
    row["memory_accesses"] = int(processes["memory_accesses"].sum())
    if "tlb_misses" in processes:
        row["tlb_misses"] = int(processes["tlb_misses"].sum())
        row["tlb_misses_per_ray"] = row["tlb_misses"] / rays if rays else float("nan")
        row["tlb_cycles"] = float(processes["tlb_cycles"].sum())
    if "migrations" in processes:
        row["migrations"] = int(processes["migrations"].sum())
    return row


def add_speedups(runs: pd.DataFrame) -> pd.DataFrame:
    """Add speed-ups, efficiency and its factors to a table of runs.

    ``runs`` needs one row with ``n_processes == 1`` per ``mapping`` (and per
    any other grouping column present in ``group``); returns a new frame.
    """
    runs = runs.copy()
    one = runs[runs["n_processes"] == 1].set_index("mapping")
    missing = sorted(set(runs["mapping"]) - set(one.index))
    if missing:
        raise InputError(f"speed-ups need a one-process run of every mapping; missing {missing}")
    t1_user = runs["mapping"].map(one["user_cycles_max"])
    t1_work = t1_user - runs["mapping"].map(one["dispatch_cycles"])
    t1_real = runs["mapping"].map(one["real_cycles"])
    best = one["user_cycles_max"].min()
    n = runs["n_processes"].astype(np.float64)
    runs["speedup_user"] = t1_user / runs["user_cycles_max"]
    runs["speedup_real"] = t1_real / runs["real_cycles"]
    runs["speedup_user_vs_best"] = best / runs["user_cycles_max"]
    runs["efficiency"] = runs["speedup_user"] / n
    runs["coherence_factor"] = t1_work / runs["work_cycles_without_dispatch"]
    runs["dispatch_factor"] = (runs["work_cycles_without_dispatch"] / runs["work_cycles"]) / (t1_work / t1_user)
    runs["dispatch_share"] = runs["dispatch_cycles"] / runs["work_cycles"]
    runs["imbalance_loss"] = 1.0 - runs["load_balance"]
    runs["coherence_loss"] = 1.0 - runs["coherence_factor"]
    runs["dispatch_loss"] = 1.0 - runs["dispatch_factor"]
    return runs
