"""Textured variants of the study's scenes, with seeded procedural textures (no image files).

* ``balls-textured``: SPD balls with a 2048 x 2048 texture on the floor
  (repeated 4 x 4 times over its 24 x 24 units) and one texture per
  recursion level of the sphereflake, 512 x 512 on the largest sphere
  halving down to 32 x 32 on the smallest ones.
* ``room-textured``: the Room stand-in with a 1024 x 1024 parquet texture on
  the floor tiles (one repeat per 2 m) and a 512 x 512 texture on the walls
  (one repeat per metre).

The geometry, lights, camera and depth are the base scene's; each textured
element gets its own material row (the base colour, times the texture).
Planar elements get (u, v) by :func:`planar_uv`.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from tracer.scenes import spd, standins
from tracer.rendering.geometry import newell_normal
from tracer.scenes.model import ElementKind, Scene
from tracer.rendering.texture import procedural_texture
from rtcommon.validate import InputError

#: textured scene name -> its base scene
TEXTURED_SCENES = {"balls-textured": "balls", "room-textured": "room"}


def planar_uv(vertices: np.ndarray, period: float) -> np.ndarray:
    """(u, v) of a planar element's vertices (n, 3): the two world coordinates
    its plane does not face most, over ``period`` (one texture repeat per
    ``period`` scene units). Returns (n, 2)."""
    vertices = np.asarray(vertices, dtype=np.float64)
    kept = [axis for axis in range(3) if axis != int(np.argmax(np.abs(newell_normal(vertices))))]
    return vertices[:, kept] / period


def add_textures(scene: Scene, images, element_texture, uv_scale, planar_period: float = 1.0) -> Scene:
    """``scene`` with textures on some elements.

    Parameters
    ----------
    scene : Scene
        Without textures of its own.
    images : sequence of ndarray, shape (H, W, 4) uint8
    element_texture : ndarray of int64, shape (n,)
        Texture of each element, -1 for none.
    uv_scale : ndarray of float64, shape (n,)
        The material's repeat factor of each textured element.
    planar_period : float
        Textured triangles and polygons get :func:`planar_uv` (u, v) with this period.

    Returns
    -------
    Scene
        Each (material row, texture, scale) used gets a material row of its own.
    """
    if scene.n_textures:
        raise InputError("add_textures: the scene already has textures")
    element_texture = np.asarray(element_texture, dtype=np.int64)
    uv_scale = np.asarray(uv_scale, dtype=np.float64)
    materials = {name: getattr(scene, name) for name in ("material_color", "material_kd", "material_ks",
                                                         "material_shine", "material_t", "material_ior")}
    n_materials = len(scene.material_kd)
    material_texture = list(np.full(n_materials, -1, dtype=np.int64))
    material_scale = list(np.ones(n_materials))
    rows = {}
    element_material = scene.element_material.copy()
    source = []  # the base row of each new row
    for e in np.flatnonzero(element_texture >= 0):
        key = (int(scene.element_material[e]), int(element_texture[e]), float(uv_scale[e]))
        if key not in rows:
            rows[key] = n_materials + len(source)
            source.append(key[0])
            material_texture.append(key[1])
            material_scale.append(key[2])
        element_material[e] = rows[key]
    extra = np.array(source, dtype=np.int64)
    new = {name: np.concatenate([values, values[extra]]) for name, values in materials.items()}
    # rows numbered by first use, unused ones dropped: SceneBuilder's canonical order, so that an NFF
    # round trip gives the same scene
    used, first_use = np.unique(element_material, return_index=True)
    order = used[np.argsort(first_use)]
    renumber = np.full(n_materials + len(source), -1, dtype=np.int64)
    renumber[order] = np.arange(order.size)
    element_material = renumber[element_material]
    new = {name: values[order] for name, values in new.items()}
    material_texture = np.array(material_texture, dtype=np.int64)[order]
    material_scale = np.array(material_scale, dtype=np.float64)[order]
    triangle_uv = scene.triangle_uv.copy()
    polygon_uv = scene.polygon_uv.copy()
    for e in np.flatnonzero(element_texture >= 0):
        kind, index = ElementKind(int(scene.element_kind[e])), int(scene.element_index[e])
        if kind == ElementKind.TRIANGLE:
            triangle_uv[index] = planar_uv(scene.triangle_vertices[index], planar_period)
        elif kind == ElementKind.POLYGON:
            first, stop = scene.polygon_offsets[index], scene.polygon_offsets[index + 1]
            polygon_uv[first:stop] = planar_uv(scene.polygon_vertices[first:stop], planar_period)
        elif kind != ElementKind.SPHERE:
            raise InputError(f"add_textures: element {e} is a {kind.name.lower()}, which this helper can't map")
    images = [np.asarray(image, dtype=np.uint8) for image in images]
    sizes = np.array([(image.shape[1], image.shape[0]) for image in images], dtype=np.int64).reshape(-1, 2)
    offsets = np.zeros(len(images) + 1, dtype=np.int64)
    np.cumsum(sizes[:, 0] * sizes[:, 1], out=offsets[1:])
    return dataclasses.replace(
        scene, element_material=element_material, **new,
        material_texture=material_texture, material_uv_scale=material_scale,
        triangle_uv=triangle_uv, polygon_uv=polygon_uv, texture_size=sizes, texture_offsets=offsets,
        texture_texels=np.concatenate([image.reshape(-1, 4) for image in images]))


def balls_textured(floor_size: int = 2048, sphere_size: int = 512) -> Scene:
    """SPD balls with a ``floor_size``-square floor texture and one texture per
    recursion level of spheres, ``sphere_size`` on the root, halving per level
    (at least 8); see the module docstring."""
    scene = spd.balls()
    n = scene.n_elements
    kinds = scene.element_kind
    radii = np.zeros(n)
    spheres = kinds == ElementKind.SPHERE
    radii[spheres] = scene.sphere_radius[scene.element_index[spheres]]
    level = np.zeros(n, dtype=np.int64)
    level[spheres] = np.rint(np.log(0.5 / radii[spheres]) / np.log(3.0)).astype(np.int64)
    n_levels = int(level.max()) + 1
    images = [procedural_texture(floor_size, seed=1)]
    images += [procedural_texture(max(8, sphere_size >> k), seed=10 + k) for k in range(n_levels)]
    element_texture = np.where(spheres, 1 + level, 0)  # the floor quad is the one non-sphere
    # the floor spans 24 units: 4 x 4 repeats of its texture
    return dataclasses.replace(add_textures(scene, images, element_texture, np.ones(n), planar_period=6.0),
                               name="balls-textured")


def room_textured(floor_size: int = 1024, wall_size: int = 512) -> Scene:
    """The Room stand-in with textured floor tiles and walls (see the module docstring)."""
    scene = standins.room()
    n = scene.n_elements
    floor = np.zeros(n, dtype=bool)
    walls = np.zeros(n, dtype=bool)
    wall_colour = np.array([0.85, 0.82, 0.74])
    for e in range(n):
        kind, index = ElementKind(int(scene.element_kind[e])), int(scene.element_index[e])
        if kind != ElementKind.POLYGON:
            continue
        first, stop = scene.polygon_offsets[index], scene.polygon_offsets[index + 1]
        vertices = scene.polygon_vertices[first:stop]
        if np.all(np.abs(vertices[:, 2]) < 1e-9):
            floor[e] = True
        elif np.allclose(scene.material_color[scene.element_material[e]], wall_colour):
            walls[e] = True
    element_texture = np.where(floor, 0, np.where(walls, 1, -1))
    # floor: one repeat per 2 m; walls: one per metre (planar period 1 m)
    scale = np.where(floor, 0.5, 1.0)
    images = [procedural_texture(floor_size, seed=3, cells=16), procedural_texture(wall_size, seed=4)]
    return dataclasses.replace(add_textures(scene, images, element_texture, scale, planar_period=1.0),
                               name="room-textured")
