"""The game bake: maps per material in the asset's UVs, its glTF output, the child process."""
