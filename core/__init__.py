"""SceneFit's science: rendering, neural textures, guidance, lighting.

Nothing in this package imports bpy; Blender data arrives as numpy arrays and dataclasses.
"""
