"""Acceleration: kd-tree builders (SAH, spatial median), node format, traversal and closest-hit queries."""
