"""kd-tree (the study's "BSP"): SAH and spatial-median builders, flat arrays.

Node layout (pbrt style, 8 bytes): ``nodes`` is (N, 2) uint32, the words and
bits named in :mod:`tracer.kd.nodes`.

* interior node: ``word0`` = the split position as float32 bits, ``word1`` =
  ``above_child << 2 | axis`` (axis 0, 1, 2); the below child is the next
  node (``index + 1``).
* leaf: ``word0`` = offset of its first entry in ``primitive_indices``,
  ``word1`` = ``count << 2 | 3``.

``primitive_indices`` (int32) holds element ids; a leaf's entries are
``primitive_indices[word0 : word0 + count]``. Split positions are rounded to
float32 *before* primitives are partitioned, so the stored plane is the plane
the build used.

Builders (``KdTreeConfig.builder``):

* ``"sah"``: surface area heuristic with an event sweep, built in
  O(N log N) as in Wald & Havran 2006 ("On building fast kd-trees for ray
  tracing, and on doing that in O(N log N)"). The events (box starts, ends,
  and flat boxes) of all three axes are sorted once, at the root. Splitting a
  node partitions its sorted event lists into the two children in order:
  a primitive entirely on one side keeps its events; a primitive straddling
  the plane is clipped to each child again, and only its new events are
  sorted (few per node) and merged with the kept ones. Leaves list element
  ids in ascending order.
  With ``clip`` on, each primitive's box is clipped to the node: polygons are
  clipped exactly (Sutherland-Hodgman), and a sphere is dropped from a node
  whose box lies entirely inside it (its surface cannot be hit there) or
  outside it. That keeps heavily overlapping spheres (SPD shells) from
  filling every leaf. Where the sweep finds no plane worth it for 8 or more
  primitives, the midplanes are also judged with the primitives clipped to
  each child.
  The trees are those of the earlier builder, which clipped every primitive
  to every node and sorted events per node (O(N log^2 N)); it lives on as
  the peer in ``tests/naive_kdtree.py``, for the tests and benchmarks. A one-sided primitive's box lies within
  the child, so clipping it again would give it back in exact arithmetic; in
  floating point, Sutherland-Hodgman against the child's faces can end a
  last bit off, so a shape reaching the split face is clipped again and a
  changed box (rare) gets new events like a straddler.
* ``"median"``: the node's longest axis (or, with ``axis_rule="cycle"``,
  axis ``depth % 3``: x, y, z, x, ...) is halved, as a 1990s BSP did; a
  node stops at ``leaf_size`` primitives, at ``tree_depth``, when the node is
  flat along its split axis, or when a split would not separate any
  primitive (with ``split_to_depth``, not then: a plain BSP of the time
  split every node holding more than ``leaf_size`` primitives down to
  ``tree_depth``, overlapping ones included).
"""
from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field, replace

import numpy as np

from rtcommon.validate import InputError, require_int, require_number
from tracer.rendering.geometry import check_coordinates, element_bounds, element_clip_shapes
from tracer.kd.build import _build_median
from tracer.kd.sah import _build_sah
from tracer.kd.split import BuildInputs, BuildParams
from tracer.scenes.model import Scene

BUILDERS = ("sah", "median")
AXIS_RULES = ("longest", "cycle")
MAX_TREE_DEPTH = 60  # the traversal stack holds 64 entries


def default_tree_depth(n_primitives: int) -> int:
    """pbrt's depth rule ``round(8 + 1.3 log2 N)``, capped at 60."""
    return int(min(MAX_TREE_DEPTH, round(8 + 1.3 * math.log2(max(n_primitives, 1)))))


@dataclass(frozen=True)
class KdTreeConfig:
    """How to build a kd-tree.

    Parameters
    ----------
    builder : {"sah", "median"}
        Surface area heuristic or spatial median (see module docstring).
    tree_depth : int or None
        Deepest node level (root 0), 1..60; ``None`` means
        :func:`default_tree_depth` of the scene's element count. (The depth
        of the ray tree is another thing: ``Scene.max_depth``.)
    leaf_size : int
        A node with at most this many primitives becomes a leaf (>= 1).
    traversal_cost, intersection_cost : float
        SAH costs of an interior-node step and of one intersection test (> 0).
    empty_bonus : float
        In [0, 1): fraction of the intersection cost forgiven for a split
        with an empty side.
    clip : bool
        Clip primitives to the node (see module docstring).
    force_split : int
        SAH only: a node holding more than this many primitives is split at
        its best plane even when the one-level cost estimate says a leaf is
        cheaper (like pbrt's "bad refines"), down to ``tree_depth``. Heavily
        overlapping primitives (SPD shells: about 90 spheres cover every
        point) only separate after several levels, which a greedy estimate
        cannot see. ``0`` disables it.
    axis_rule : {"longest", "cycle"}
        Median builder only: halve the node's longest axis, or cycle the
        axes with depth (x at the root). The SAH builder judges all axes.
    split_to_depth : bool
        Median builder only: split a node of more than ``leaf_size``
        primitives even where the plane separates none of them, down to
        ``tree_depth``.
    """

    builder: str = "sah"
    tree_depth: int | None = None
    leaf_size: int = 1
    traversal_cost: float = 1.0
    intersection_cost: float = 1.5
    empty_bonus: float = 0.5
    clip: bool = True
    force_split: int = 0
    axis_rule: str = "longest"
    split_to_depth: bool = False

    def __post_init__(self):
        if self.builder not in BUILDERS:
            raise InputError(f"KdTreeConfig.builder must be one of {BUILDERS}, got {self.builder!r}")
        if self.tree_depth is not None:
            object.__setattr__(self, "tree_depth",
                               require_int("KdTreeConfig.tree_depth", self.tree_depth, 1, MAX_TREE_DEPTH))
        object.__setattr__(self, "leaf_size", require_int("KdTreeConfig.leaf_size", self.leaf_size, 1))
        for name in ("traversal_cost", "intersection_cost"):
            value = require_number(f"KdTreeConfig.{name}", getattr(self, name), 0)
            if value == 0.0:
                raise InputError(f"KdTreeConfig.{name} must be a finite number > 0, got {getattr(self, name)!r}")
            object.__setattr__(self, name, value)
        eb = float(self.empty_bonus)
        if not 0.0 <= eb < 1.0:
            raise InputError(f"KdTreeConfig.empty_bonus must be in [0, 1), got {self.empty_bonus!r}")
        object.__setattr__(self, "empty_bonus", eb)
        object.__setattr__(self, "clip", bool(self.clip))
        force_split = require_int("KdTreeConfig.force_split", self.force_split, 0)
        object.__setattr__(self, "force_split", force_split if force_split else 2**62)
        if self.axis_rule not in AXIS_RULES:
            raise InputError(f"KdTreeConfig.axis_rule must be one of {AXIS_RULES}, got {self.axis_rule!r}")
        object.__setattr__(self, "split_to_depth", bool(self.split_to_depth))

    def to_dict(self) -> dict:
        """The configuration as plain Python values."""
        return asdict(self)


@dataclass(eq=False)
class KdTree:
    """A built kd-tree (see module docstring for the node layout).

    Attributes
    ----------
    nodes : ndarray, shape (N, 2) uint32
    primitive_indices : ndarray, shape (E,) int32
        Element ids referenced by leaves.
    bounds : ndarray, shape (2, 3) float64
        Root box (lo, hi).
    config : KdTreeConfig
        The configuration used, with ``tree_depth`` resolved.
    stats : dict
        ``nodes``, ``leaves``, ``empty_leaves``, ``depth`` (deepest leaf),
        ``mean_primitives_per_leaf`` (over non-empty leaves), ``references``
        (entries in ``primitive_indices``), ``sah_cost`` (expected cost of a
        ray through the root under the configured costs), ``build_seconds``.
    """

    nodes: np.ndarray
    primitive_indices: np.ndarray
    bounds: np.ndarray
    config: KdTreeConfig
    stats: dict = field(default_factory=dict)

    @property
    def split_view(self) -> np.ndarray:
        """``nodes`` viewed as float32 (N, 2); column 0 holds interior splits."""
        return self.nodes.view(np.float32)


def build_kdtree(scene: Scene, config: KdTreeConfig | None = None) -> KdTree:
    """Build a kd-tree over all elements of ``scene``.

    Parameters
    ----------
    scene : Scene
    config : KdTreeConfig, optional
        Defaults to ``KdTreeConfig()`` (SAH).

    Returns
    -------
    KdTree
    """
    config = resolve_config(config, scene.n_elements)
    start = time.perf_counter()
    inputs = builder_inputs(scene)
    builder = _build_sah if config.builder == "sah" else _build_median
    nodes, pidx, leaves, empty, deepest, cost = builder(inputs, build_params(config))
    seconds = time.perf_counter() - start
    filled = leaves - empty
    stats = {
        "nodes": int(len(nodes)),
        "leaves": int(leaves),
        "empty_leaves": int(empty),
        "depth": int(deepest),
        "mean_primitives_per_leaf": float(len(pidx) / filled) if filled else 0.0,
        "references": int(len(pidx)),
        "sah_cost": float(cost),
        "build_seconds": float(seconds),
    }
    return KdTree(nodes=nodes, primitive_indices=pidx,
                  bounds=np.stack([inputs.root_lo, inputs.root_hi]).astype(np.float64),
                  config=config, stats=stats)


def resolve_config(config: KdTreeConfig | None, n_elements: int) -> KdTreeConfig:
    """``config`` (default ``KdTreeConfig()``) with ``tree_depth`` resolved for ``n_elements``.

    Raises
    ------
    ValueError
        If ``config`` is not a :class:`KdTreeConfig` or the scene has too
        many elements for the tree's 30-bit counts.
    """
    if config is None:
        config = KdTreeConfig()
    if not isinstance(config, KdTreeConfig):
        raise InputError(f"config must be a KdTreeConfig, got {type(config).__name__}")
    if n_elements >= 2**30:
        raise InputError(f"Scene.element_kind: too many elements for the kd-tree ({n_elements})")
    if config.tree_depth is None:
        config = replace(config, tree_depth=default_tree_depth(n_elements))
    return config


def build_params(config: KdTreeConfig) -> BuildParams:
    """The builder kernels' parameters of a resolved ``config`` (see :func:`resolve_config`)."""
    return BuildParams(config.tree_depth, config.leaf_size, config.traversal_cost, config.intersection_cost,
                       config.empty_bonus, config.clip, config.force_split, config.axis_rule == "cycle",
                       config.split_to_depth)


def builder_inputs(scene: Scene) -> BuildInputs:
    """The builder kernels' scene arrays: element boxes, clip shapes and the root box.

    Raises
    ------
    ValueError
        If a coordinate or size is not finite or too large
        (:func:`tracer.rendering.geometry.check_coordinates`).
    """
    check_coordinates(scene)
    lo, hi = element_bounds(scene)
    if scene.n_elements:
        root_lo, root_hi = lo.min(axis=0), hi.max(axis=0)
    else:
        root_lo, root_hi = np.zeros(3), np.zeros(3)
    clip_off, clip_v, spheres = element_clip_shapes(scene)
    return BuildInputs(lo, hi, clip_off, clip_v, spheres, root_lo, root_hi)
