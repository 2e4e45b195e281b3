"""The trace format: record kinds and packing, counters, and per-pixel access logs (AccessTrace)."""
