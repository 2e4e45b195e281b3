"""
A cache what-if: when would coherence matter?
=============================================

A :class:`analyses.whatif.WhatIf` study varies one or more choices of a base
:class:`analyses.Experiment` over a grid and replays the same trace at every
point. Each row of :func:`analyses.whatif.run_whatif`'s table says how much
efficiency a mapping lost to imbalance and to coherence at that point, and
which loss was larger. ``coherence whatif latency`` runs the built-in version
of this study; here the memory latency grows from the 21164's 80 cycles to
1,280 on a 64×64 tetra at 8 processes.
"""
from analyses.whatif import WhatIf, run_whatif

study = WhatIf.of("latency", {"memory_latency": [80, 320, 1280]}, scene="tetra", size=64,
                  mappings=("S", "P", "B"))
table = run_whatif(study, n_jobs=1, progress=False)
print(table[["memory_latency", "mapping", "imbalance_loss", "coherence_loss", "verdict"]]
      .round(3).to_string(index=False))

# %%
# Solid lines: efficiency lost to imbalance; dashed: to coherence. A slower
# memory raises every mapping's coherence loss, the pixel mapping P's most:
# each of its processes renders every eighth pixel, so the data of
# neighbouring pixels is fetched into eight caches instead of one. Strips
# and blocks lose more than half their efficiency to imbalance on this
# small image whatever the memory does.
from analyses.maps import plot_loss_lines

plot_loss_lines(table, "memory_latency")
