"""Tracer: scenes, NFF, kd-tree and the instrumented renderer."""
from tracer.scenes.model import Camera, ElementKind, Scene

__all__ = ["Camera", "ElementKind", "Scene"]
