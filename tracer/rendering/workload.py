"""Workload presets: which tracer the renderer imitates, today's or the study's.

A :class:`Workload` bundles the kd-tree rule and the behaviour levers of the
tracer that :func:`tracer.rendering.render.render` imitates. Three presets
(:data:`WORKLOADS`):

* ``"modern"``: today's tracer, the default: SAH kd-tree, shadow rays stop
  at the first hit found, only scene records are logged.
* ``"study1997"``: a mid-1990s BSP tracer like the one of Havran & Žára's
  study: a spatial-median tree with one parameter set for every scene
  (chosen by ``benchmarks/study_tree_search.py``, see
  ``docs/study_tree_search.csv``): axes cycled, every node of more than 32
  objects split down to depth 16, objects sorted into children by their
  bounding boxes (not clipped); shadow rays that look for the nearest hit;
  and the tracer's own per-ray data logged (ray stack, hit records, shading
  temporaries, frame-buffer writes; :mod:`tracer.trace.records`).
* ``"pathtrace"``: today's tree and first-hit shadow rays under the path
  tracer (:mod:`tracer.rendering.pathtrace`) instead of Whitted's rules:
  ``RenderOptions.spp`` samples per pixel, incoherent bounces, and per-ray
  segments saved with the trace.

What a "test" is (decided before any fitting, and kept)
-------------------------------------------------------
The study's column is "intersection tests", and its tracer used a BSP tree.
A test is therefore **one call of a ray-primitive intersection routine**
(``Counter.TESTS_*``), counted every time it happens: an object that lies in
several leaves a ray visits is tested (and counted) again, as it was in a
tracer without mailboxes. Visits of BSP nodes are not tests: a BSP node is a
plane, and stepping through it (Havran's "traversal step", counted apart
from "ray-object intersection tests" in his later methodology) tests nothing
against the ray. Bounding-box tests are not counted either: a BSP has no
boxes to test, and the study does not mention any. The one hint the other
way, tetra's 7.6 M equalling Haines's count of *box* tests with a
Goldsmith-Salmon hierarchy (Eric Haines's SPD notes), concerns a different
acceleration structure and is taken as a coincidence. This definition is
also what every other part of the project (the cost model, the paper's
comparison table) calls an intersection test.

Levers left out: mailboxing (neither preset uses it; today's tracer already
tests an object again in every leaf) and a bounding-box test before each
object test (not a test by the definition above, so it could not be chosen
by the search; its memory cost belongs to the object record's size in
:mod:`coherence.layout`).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

from rtcommon.validate import InputError, require_bool
from tracer.kd.tree import KdTreeConfig

__all__ = ["Workload", "WORKLOADS", "STUDY_TREE", "RENDERERS", "get_workload"]

#: The renderers a workload may use.
RENDERERS = ("whitted", "pathtrace")


@dataclass(frozen=True)
class Workload:
    """The tracer a render imitates.

    Parameters
    ----------
    name : str
        Recorded in every output's parameters.
    kd_config : KdTreeConfig
        The tree rule, the same for every scene.
    shadow_nearest : bool
        Shadow rays look for the nearest hit before the light (a tracer
        that used one ``intersect`` routine for every ray) instead of
        stopping at the first hit found.
    log_ray_data : bool
        Log the tracer's own per-ray data besides the scene records: ray
        stack pushes and pops, hit-record writes and reads, shading
        temporaries and one frame-buffer write per pixel
        (:class:`tracer.trace.records.RecordKind` 9-12).
    renderer : {"whitted", "pathtrace"}
        The renderer: Whitted's rules (:mod:`tracer.rendering.whitted`) or
        the path tracer (:mod:`tracer.rendering.pathtrace`). Left out of
        :meth:`to_dict` when ``"whitted"``, so the Whitted presets' records are
        those of before the path tracer existed.
    """

    name: str
    kd_config: KdTreeConfig
    shadow_nearest: bool = False
    log_ray_data: bool = False
    renderer: str = "whitted"

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name:
            raise InputError(f"Workload.name must be a non-empty string, got {self.name!r}")
        if not isinstance(self.kd_config, KdTreeConfig):
            raise InputError(f"Workload.kd_config must be a KdTreeConfig, got {type(self.kd_config).__name__}")
        for lever in ("shadow_nearest", "log_ray_data"):
            object.__setattr__(self, lever, require_bool(f"Workload.{lever}", getattr(self, lever)))
        if self.renderer not in RENDERERS:
            raise InputError(f"Workload.renderer must be one of {', '.join(RENDERERS)}, got {self.renderer!r}")

    def to_dict(self) -> dict:
        """The workload as plain Python values (for output metadata)."""
        out = asdict(self)
        out["kd_config"] = self.kd_config.to_dict()
        if self.renderer == "whitted":
            del out["renderer"]
        return out


#: The study-era tree: one parameter set for all five scenes, the least mean
#: squared log error of tests against the study's over balls, tetra and shell
#: in ``benchmarks/study_tree_search.py`` (table: ``docs/study_tree_search.csv``).
STUDY_TREE = KdTreeConfig(builder="median", tree_depth=16, leaf_size=32, clip=False, axis_rule="cycle",
                          split_to_depth=True)

WORKLOADS = {
    "modern": Workload("modern", KdTreeConfig()),
    "study1997": Workload("study1997", STUDY_TREE, shadow_nearest=True, log_ray_data=True),
    "pathtrace": Workload("pathtrace", KdTreeConfig(), renderer="pathtrace"),
}


def get_workload(name_or_workload) -> Workload:
    """A preset of :data:`WORKLOADS` by name, or a :class:`Workload` as is.

    Raises
    ------
    ValueError
        For any other name or type.
    """
    if isinstance(name_or_workload, Workload):
        return name_or_workload
    if isinstance(name_or_workload, str) and name_or_workload in WORKLOADS:
        return WORKLOADS[name_or_workload]
    raise InputError(f"workload must be one of {', '.join(WORKLOADS)} or a Workload, got {name_or_workload!r}")
