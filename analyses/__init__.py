"""Analyses: per-scene report, paper reproduction, what-if studies."""
