"""
Texture layouts: how the texel order changes texture misses
===========================================================

On a textured scene the trace also logs every texel read. How those reads
hit the caches depends on the texel order in memory (row-major ``linear``,
square tiles ``tiled4``, ``morton``), on the order in which a process visits
pixels (its mapping) and on the cache. A what-if grid over
``texture_layout`` replays the same trace under each order; its table gives,
per cache level, texel misses per texel read. ``coherence whatif texture``
runs the built-in study; here a 32×32 image of the textured balls scene.
"""
from analyses.whatif import WhatIf, run_whatif

study = WhatIf.of("texels", {"texture_layout": ["linear", "tiled4", "morton"]}, scene="balls-textured",
                  size=32, mappings=("S", "P", "hilbert"))
table = run_whatif(study, n_jobs=1, progress=False)
print(table[["texture_layout", "mapping", "texel_L1_misses_per_access", "texture_L1_miss_share"]]
      .round(4).to_string(index=False))

# %%
# Texel misses per texel read in the 8 KB first-level cache, per texel
# order and mapping.
from analyses.maps import plot_texel_misses

plot_texel_misses(table, "L1")
