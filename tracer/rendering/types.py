"""The renderer's kernel vocabulary: ray kinds, the columns of its flat arrays, and its argument bundles.

:func:`tracer.rendering.render.render` and its compiled kernels share these; they live
apart so that the kernels' module holds only the tracing itself.
"""
from __future__ import annotations

import enum
from typing import NamedTuple

import numpy as np

from tracer.kd.traverse import TraversalStack


class RayType(enum.IntEnum):
    """Kinds of rays on the ray stack (shadow rays are traced at once, never stacked)."""

    PRIMARY = 0
    REFLECTION = 1
    REFRACTION = 2


class RayColumn(enum.IntEnum):
    """Columns of the ray stack (S, N_RAY_COLUMNS) float64 of :func:`tracer.rendering.whitted._trace_sample`."""

    ORIGIN = 0     # x; y and z follow
    DIRECTION = 3  # x, unit; y and z follow
    WEIGHT = 6     # red; green and blue follow
    DEPTH = 9      # primary = 1
    TYPE = 10      # a RayType value
    CONE_WIDTH = 11   # ray cone: width at the origin (scene units)
    CONE_SPREAD = 12  # ray cone: spread angle (radians)


N_RAY_COLUMNS = 13


class MaterialColumn(enum.IntEnum):
    """Columns of :attr:`Shading.materials` (M, N_MATERIAL_COLUMNS)."""

    COLOR = 0  # red; green and blue follow
    KD = 3
    KS = 4
    SHINE = 5
    TRANSMIT = 6
    IOR = 7


class LightColumn(enum.IntEnum):
    """Columns of :attr:`Shading.lights` (L, N_LIGHT_COLUMNS)."""

    POSITION = 0  # x; y and z follow
    COLOR = 3  # red, scaled like the ambient level (Shading.ambient); green and blue follow


N_MATERIAL_COLUMNS = 8
N_LIGHT_COLUMNS = 6


class Shading(NamedTuple):
    """What shading reads: materials per element, the lights and the textures (see :func:`tracer.rendering.shading.shading_of`).

    Flat (arrays and scalars only): a bundle inside a bundle can't reach a
    parallel kernel's loop body. The texture fields are those of
    :class:`tracer.rendering.uv.UvMaps` and :class:`tracer.rendering.texture.MipChains`, so the
    texture kernels read this bundle as either.
    """

    element_material: np.ndarray  #: (n,) int64 row of ``materials`` of each element
    materials: np.ndarray         #: (M, N_MATERIAL_COLUMNS) float64, columns MaterialColumn
    lights: np.ndarray            #: (L, N_LIGHT_COLUMNS) float64, columns LightColumn
    ambient: float                #: ambient level, SPD's ``sqrt(L) / (2 L)`` (0.5 without lights)
    background: np.ndarray        #: (3,) float64 colour of rays that hit nothing
    material_texture: np.ndarray   #: (M,) int64 texture of each material, -1 for none
    material_uv_scale: np.ndarray  #: (M,) float64 repeats of the texture over (u, v)
    plane_map: np.ndarray          #: (n, 2, 4) float64 UvMaps.plane_map
    density: np.ndarray            #: (n,) float64 UvMaps.density
    texels: np.ndarray             #: (N, 4) uint8 MipChains.texels
    level_first: np.ndarray        #: (K + 1,) int64 MipChains.level_first
    level_width: np.ndarray        #: (K,) int64
    level_height: np.ndarray       #: (K,) int64
    texture_level: np.ndarray      #: (X + 1,) int64 MipChains.texture_level
    texture_filter: int            #: a TextureFilter value


class RenderParams(NamedTuple):
    """Per-render scalars, as the kernels read them."""

    n_samples: int    #: samples in the image (W x H, or (W + 1) x (H + 1) with corner rays)
    hither: float     #: primary rays ignore hits closer than this
    epsilon: float    #: secondary and shadow rays ignore hits closer than this
    max_depth: int    #: ray-tree depth (primary = 1)
    shadow_anyhit: bool  #: shadow rays stop at the first hit found (else they find the nearest)
    log_ray_data: bool   #: log the tracer's own per-ray data (RecordKind.RAY_STACK .. FRAME_BUFFER)
    pixel_spread: float  #: spread angle of a primary ray's cone (radians): the angle between pixel centres


class SampleOutputs(NamedTuple):
    """Per-sample outputs of the render kernels."""

    image: np.ndarray     #: (n_samples, 3) float64 linear RGB
    counters: np.ndarray  #: (n_samples, N_COUNTERS) int64
    counts: np.ndarray    #: (n_samples,) int64 records produced


class WorkItems(NamedTuple):
    """Parallel work items of :func:`tracer.rendering.whitted.render_kernel`: ``CHUNK`` samples each.

    Item ``k`` covers samples ``start[k] .. start[k] + CHUNK`` (fewer at the
    end) and logs them into ``records[base[k] : base[k] + capacity[k]]``;
    ``used[k]`` is how many records it produced (more than ``capacity[k]``:
    the slot overflowed, nothing past it stored).
    """

    start: np.ndarray     #: (K,) int64 first sample
    base: np.ndarray      #: (K,) int64 first record position of the slot
    capacity: np.ndarray  #: (K,) int64 slot size
    used: np.ndarray      #: (K,) int64 output


class SampleRange(NamedTuple):
    """The samples ``first .. stop - 1`` of one work item, traced one after another."""

    first: int
    stop: int


class SampleScratch(NamedTuple):
    """Per-thread scratch of :func:`tracer.rendering.whitted._trace_sample` (allocated once per work item)."""

    counters: np.ndarray  #: (N_COUNTERS,) int64 of the sample being traced
    stack: TraversalStack
    rays: np.ndarray      #: (2 max_depth + 2, N_RAY_COLUMNS) float64 ray stack
