"""Run a stream through pycachesim; executed in a subprocess by tests/oracle.py.

Usage: python run_pycachesim.py ORACLE_DIR CONFIG.json ADDRESSES.npy OUT.json

ORACLE_DIR holds pycachesim (installed with ``pip install --target``). Its
import name is ``cachesim`` like ours, so this script puts ORACLE_DIR first on
sys.path and checks that the module it got really comes from there.
"""
import json
import sys
import time
from pathlib import Path

oracle_dir, config_path, addresses_path, out_path = sys.argv[1:5]
sys.path.insert(0, oracle_dir)

import numpy as np  # noqa: E402
import cachesim  # noqa: E402

if not Path(cachesim.__file__).resolve().is_relative_to(Path(oracle_dir).resolve()):
    sys.exit(f"imported cachesim from {cachesim.__file__}, not from the oracle folder {oracle_dir}")

from cachesim import Cache, CacheSimulator, MainMemory  # noqa: E402

config = json.loads(Path(config_path).read_text())
addresses = np.load(addresses_path).tolist()  # plain ints: pycachesim iterates a Python sequence

below = None
caches = []
for level in reversed(config["levels"]):
    ways = level["size"] // level["line_size"] if level["assoc"] == "full" else level["assoc"]
    sets = level["size"] // (level["line_size"] * ways)
    cache = Cache(level["name"], sets, ways, level["line_size"], level["policy"].upper(),
                  store_to=below, load_from=below)
    caches.insert(0, cache)
    below = cache
memory = MainMemory()
memory.load_to(caches[-1])
memory.store_from(caches[-1])
simulator = CacheSimulator(caches[0], memory)

start = time.perf_counter()
simulator.load(addresses)  # the bulk path: one C loop over the whole sequence
seconds = time.perf_counter() - start

stats = [cache.stats() for cache in caches]
result = {
    "seconds": seconds,
    "accesses": [s["LOAD_count"] for s in stats],
    "hits": [s["HIT_count"] for s in stats],
    "misses": [s["MISS_count"] for s in stats],
    "evictions": [s["EVICT_count"] for s in stats],
}
Path(out_path).write_text(json.dumps(result))
