"""Development-only helpers, kept out of the extension zip (blender_manifest.toml excludes /devtools/).

tiny_models.py    tiny random-weight Stable Diffusion 2 stand-ins for tests and benchmarks
example_asset.py  the demo's example asset, made by Blender (it resets Blender's open file, so it
                  runs in a child process)
"""
