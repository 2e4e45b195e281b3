"""
One scene's coherence report from Python
========================================

:func:`analyses.build_report` renders a scene once with the instrumented
tracer, replays every pixel's logged reads under each mapping (strips S,
pixels P, rows R, blocks B; dynamic blocks DB need more than one 32×32
block per process, so a larger image) on a simulated 8-CPU Alpha
machine, and splits every run's efficiency into load balance × coherence ×
dispatch. The command ``coherence report tetra`` does the same and writes
the page; here the report stays in Python, at 32×32 pixels.
"""
from analyses import Experiment, build_report

experiment = Experiment(scene="tetra", size=32, mappings=("S", "P", "R", "B"), n_processes=(1, 2, 4, 8),
                        background=0, progress=False)
report = build_report(experiment)
print(report.verdict.headline)

# %%
# The run table: one row per mapping and process count. ``efficiency`` is
# the speed-up over the process count; it is the product of the three
# factors beside it.
columns = ["mapping", "n_processes", "speedup_user", "efficiency", "load_balance", "coherence_factor",
           "dispatch_factor"]
runs = report.runs[columns]
print(runs[runs["n_processes"] == 8].round(3).to_string(index=False))

# %%
# Speed-up against process count, one line per mapping. Strips give some
# processes the sky and others the tetrahedra: on this small image the
# imbalance, not the caches, keeps S and B far below the ideal line.
from analyses.plots import plot_speedup

plot_speedup(report.runs, n_cpus=experiment.n_cpus)
