"""Scene input: the scene model, NFF and OBJ readers and writer, SPD generators, stand-ins, textures."""
