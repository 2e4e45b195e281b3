"""Rendering: the instrumented Whitted renderer, shading, camera, intersection tests, textures."""
