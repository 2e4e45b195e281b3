"""What the renderer's shading reads, gathered from a scene, and the textured part of shading.

:func:`shading_of` checks a scene's materials, lights and textures and makes
the flat :class:`~tracer.rendering.types.Shading` bundle the kernels read: the
lights scaled by SPD's rule (``sqrt(L) / (2 L)`` for ``L`` lights, the
ambient level too), the (u, v) maps of the textured elements and every
texture's mip pyramid. :func:`texture_colour` is the compiled lookup of one
textured hit: its (u, v), its level of detail from the ray cone's footprint
(``width * uv_scale * sqrt(density * W * H) / |cos|`` level-0 texels, the
level its log2; ``docs/textures.md``) and the filtered texels, logged.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from rtcommon.jit import NO_REFCOUNTS
from tracer.rendering.types import N_LIGHT_COLUMNS, N_MATERIAL_COLUMNS, Shading
from tracer.scenes.model import Scene
from tracer.rendering.texture import TextureFilter, filtered_lookup, mip_chains
from tracer.rendering.uv import surface_uv, uv_maps
from rtcommon.validate import InputError


def shading_of(scene: Scene, texture_filter: TextureFilter = TextureFilter.TRILINEAR) -> Shading:
    """Check ``scene``'s materials and gather what shading reads.

    Lights are scaled by SPD's rule (``sqrt(L) / (2 L)`` for ``L`` lights,
    the ambient level too).
    """
    n = scene.n_elements
    if scene.element_material.shape != (n,):
        raise InputError(f"Scene.element_material must have shape ({n},)")
    emat = np.ascontiguousarray(scene.element_material, dtype=np.int64)
    mats = np.column_stack([scene.material_color.reshape(-1, 3), scene.material_kd, scene.material_ks,
                            scene.material_shine, scene.material_t, scene.material_ior]).astype(np.float64)
    mats = np.ascontiguousarray(mats.reshape(-1, N_MATERIAL_COLUMNS))
    if n and (emat.min() < 0 or emat.max() >= len(mats)):
        raise InputError("Scene.element_material refers to a material row that does not exist")
    n_lights = scene.n_lights
    scale = math.sqrt(n_lights) / (2.0 * n_lights) if n_lights else 0.5
    lights = np.ascontiguousarray(np.column_stack([scene.light_position.reshape(-1, 3),
                                                   scene.light_color.reshape(-1, 3) * scale])
                                  .reshape(-1, N_LIGHT_COLUMNS))
    background = np.ascontiguousarray(np.asarray(scene.background, dtype=np.float64).reshape(3))
    return Shading(emat, mats, lights, scale, background, *_texturing(scene, emat, len(mats), texture_filter))


def _texturing(scene: Scene, element_material: np.ndarray, n_materials: int, texture_filter) -> tuple:
    """Check ``scene``'s textures and gather what textured shading reads (the
    texture fields of :class:`Shading`, in order)."""
    material_texture = np.asarray(scene.material_texture, dtype=np.int64)
    uv_scale = np.asarray(scene.material_uv_scale, dtype=np.float64)
    if material_texture.size == 0:  # a scene without the texture fields
        material_texture = np.full(n_materials, -1, dtype=np.int64)
        uv_scale = np.ones(n_materials)
    if material_texture.shape != (n_materials,) or uv_scale.shape != (n_materials,):
        raise InputError(f"Scene.material_texture and material_uv_scale must have shape ({n_materials},)")
    if n_materials and (material_texture.min() < -1 or material_texture.max() >= scene.n_textures):
        raise InputError(f"Scene.material_texture names a texture that does not exist "
                         f"(the scene has {scene.n_textures})")
    if not (np.isfinite(uv_scale).all() and (uv_scale > 0).all()):
        raise InputError("Scene.material_uv_scale must be positive and finite")
    textured = np.flatnonzero(material_texture[element_material] >= 0)
    return (np.ascontiguousarray(material_texture), np.ascontiguousarray(uv_scale), *uv_maps(scene, textured),
            *mip_chains(scene), int(TextureFilter(texture_filter)))


@njit(cache=True, error_model="numpy", **NO_REFCOUNTS)
def texture_colour(shading, material, kind, element, geo, hit, footprint, log, pos, cnt):
    """The texture colour of ``material`` at ``hit`` of ``element`` (of ``kind``), and the next record position.

    (u, v) come from the surface (:func:`tracer.rendering.uv.surface_uv`); the level of
    detail from a ray cone of width ``footprint[0]`` meeting the surface at
    cosine ``footprint[1]`` (module docstring). Returns ``r, g, b, pos``.
    """
    hx, hy, hz = hit
    cone_width, cosine = footprint
    texture = shading.material_texture[material]
    scale = shading.material_uv_scale[material]
    u, v = surface_uv(kind, element, geo.element_index[element], geo, shading, hx, hy, hz)
    finest = shading.texture_level[texture]
    texels_per_unit = scale * math.sqrt(shading.density[element] * shading.level_width[finest]
                                        * shading.level_height[finest])
    footprint_texels = cone_width * texels_per_unit / max(abs(cosine), 1e-6)
    detail = math.log2(footprint_texels) if footprint_texels > 0.0 else 0.0
    return filtered_lookup(shading, texture, u * scale, v * scale, detail, shading.texture_filter, log, pos, cnt)
