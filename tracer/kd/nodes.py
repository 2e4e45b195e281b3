"""The kd-tree's node format: named words and bits, and inline accessors.

A node is two uint32 words (8 bytes, pbrt style); ``nodes`` is (N, 2) uint32:

* interior node: word :data:`SPLIT_WORD` holds the split position as float32
  bits, word :data:`LINK_WORD` holds ``above_child << FLAG_BITS | axis``
  (axis 0, 1, 2); the below child is the next node (``index + 1``).
* leaf: word :data:`OFFSET_WORD` holds the offset of its first entry in
  ``primitive_indices``, word :data:`LINK_WORD` holds
  ``count << FLAG_BITS | LEAF_FLAG``.

Builders and the traversal read and write nodes only through the helpers
here, which compile inline into their kernels.
"""
from __future__ import annotations

import numpy as np
from numba import njit

#: word of an interior node holding the split position (float32 bits)
SPLIT_WORD = 0
#: word of a leaf holding the offset of its first ``primitive_indices`` entry
OFFSET_WORD = 0
#: word holding the axis or leaf flag (low bits) and a child or count (high bits)
LINK_WORD = 1
#: uint32 words per node
NODE_WORDS = 2
#: low bits of :data:`LINK_WORD` that hold the axis or :data:`LEAF_FLAG`
FLAG_BITS = 2
FLAG_MASK = (1 << FLAG_BITS) - 1
#: flag value (in place of an axis) that marks a leaf
LEAF_FLAG = 3


@njit(cache=True, inline="always")
def is_leaf(nodes, node):
    """Whether ``node`` of ``nodes`` (N, 2) uint32 is a leaf."""
    return (nodes[node, LINK_WORD] & FLAG_MASK) == LEAF_FLAG


@njit(cache=True, inline="always")
def node_axis(nodes, node):
    """Split axis (0, 1, 2) of interior ``node``."""
    return np.int64(nodes[node, LINK_WORD] & FLAG_MASK)


@njit(cache=True, inline="always")
def below_child(node):
    """The child of interior ``node`` below its plane (stored next to it)."""
    return node + 1


@njit(cache=True, inline="always")
def above_child(nodes, node):
    """The child of interior ``node`` above its plane."""
    return np.int64(nodes[node, LINK_WORD] >> FLAG_BITS)


@njit(cache=True, inline="always")
def split_position(splits, node):
    """Split plane of interior ``node``; ``splits`` is ``nodes`` viewed as float32."""
    return np.float64(splits[node, SPLIT_WORD])


@njit(cache=True, inline="always")
def leaf_count(nodes, node):
    """Number of ``primitive_indices`` entries of leaf ``node``."""
    return np.int64(nodes[node, LINK_WORD] >> FLAG_BITS)


@njit(cache=True, inline="always")
def leaf_offset(nodes, node):
    """Position of the first ``primitive_indices`` entry of leaf ``node``."""
    return np.int64(nodes[node, OFFSET_WORD])


@njit(cache=True, inline="always")
def set_leaf(nodes, node, offset, count):
    """Make ``node`` a leaf of ``count`` entries from ``primitive_indices[offset]``."""
    nodes[node, OFFSET_WORD] = np.uint32(offset)
    nodes[node, LINK_WORD] = np.uint32((count << FLAG_BITS) | LEAF_FLAG)


@njit(cache=True, inline="always")
def set_interior(nodes, node, split_bits, axis):
    """Make ``node`` an interior node on ``axis`` at the float32 bits ``split_bits``.

    Its above child is linked later by :func:`set_above_child`.
    """
    nodes[node, SPLIT_WORD] = split_bits
    nodes[node, LINK_WORD] = np.uint32(axis)


@njit(cache=True, inline="always")
def set_above_child(nodes, node, child):
    """Link ``child`` as the above child of interior ``node``."""
    nodes[node, LINK_WORD] |= np.uint32(child << FLAG_BITS)
