"""The study's five scenes: names, the one alias, and its scene table.

Havran & Žára's table, verbatim, is the single home of these
facts: the scene loader takes names, depths and element counts from here, the
stand-ins their element targets, and the paper reproduction its comparison
table and fitting targets (the sequential Strip times).
"""
from __future__ import annotations

from dataclasses import dataclass

__all__ = ["PAPER_SCENES", "SCENE_ALIASES", "StudyScene", "STUDY_SCENES", "PAPER_DEPTH", "PAPER_ELEMENTS",
           "canonical_scene_name"]


@dataclass(frozen=True)
class StudyScene:
    """One row of the study's scene table.

    Attributes
    ----------
    name : str
    geometry : str
        What the scene is made of, in the study's words.
    elements, lights : int
    tests_1e6 : float
        Intersection tests of the study's run, in millions.
    max_depth : int
        Ray-tree depth (primary rays are depth 1).
    sequential_seconds : float
        Sequential real time with the Strip mapping at 512x512.
    """

    name: str
    geometry: str
    elements: int
    lights: int
    tests_1e6: float
    max_depth: int
    sequential_seconds: float


STUDY_SCENES = {scene.name: scene for scene in (
    StudyScene("balls", "spheres (SPD sphereflake)", 7382, 3, 193.0, 2, 345.8),
    StudyScene("tetra", "triangles (SPD tetra)", 4096, 1, 7.6, 2, 28.8),
    StudyScene("shell", "spheres (SPD shells)", 5761, 1, 212.2, 2, 403.0),
    StudyScene("room", "polygon meshes (CAAD interior)", 7786, 3, 114.4, 4, 365.7),
    StudyScene("fluid", "spheres (fluid-dynamics visualisation)", 2899, 2, 29.3, 5, 97.5),
)}

PAPER_SCENES = tuple(STUDY_SCENES)
PAPER_DEPTH = {name: scene.max_depth for name, scene in STUDY_SCENES.items()}
PAPER_ELEMENTS = {name: scene.elements for name, scene in STUDY_SCENES.items()}

#: Other spellings of study scene names: SPD's generator is called "shells".
SCENE_ALIASES = {"shells": "shell"}


def canonical_scene_name(name: str) -> str:
    """``name`` lower-cased, with :data:`SCENE_ALIASES` resolved (any other text is returned lower-cased)."""
    lowered = str(name).lower()
    return SCENE_ALIASES.get(lowered, lowered)
