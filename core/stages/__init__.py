"""The stages, one module or package each: camera, convert, light, adapt, compose, bake."""
