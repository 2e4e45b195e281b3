"""Tracer: scenes, NFF, kd-tree and the instrumented renderer."""
from tracer.scene import Camera, ElementKind, Scene

__all__ = ["Camera", "ElementKind", "Scene"]
