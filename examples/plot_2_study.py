"""
The study reproduced, at a tiny size
====================================

:func:`analyses.paper.reproduce` is what ``coherence paper`` runs: the
study's five scenes on its machine, the cost model calibrated to the study's
five sequential Strip times (and nothing else), then every mapping at every
process count. The study used 512×512 pixels; here its five scenes run at
32×32 with 1, 4 and 8 processes (no DB: its 32×32 blocks need a larger
image), which is enough to see the pipeline but not
the study's numbers (the results pages hold larger generated runs).
"""
from analyses.paper import reproduce

result = reproduce(size=32, mappings=("S", "P", "R", "B"), n_processes=(1, 4, 8), progress=False)

# %%
# The study's table beside ours: intersection tests (ours at this image
# size), the study's sequential times, the targets scaled to this image size
# by pixel count, and the times the fitted costs give.
columns = ["scene", "study_tests_1e6", "our_tests_1e6", "study_seconds", "target_seconds", "fitted_seconds"]
print(result.table[columns].round(3).to_string(index=False))

# %%
# Real-time speed-up per scene, as the study plotted it.
from analyses.paper_output import speedup_figure

speedup_figure(result.runs, "speedup_real")
