"""The scene's geometry, in one place: the photo camera, the floor, where the asset stands, the
environment map's convention and the compositing mattes. Lighting, guidance, compose, adapt and
blender_io import it; it imports no stage (tests/architecture/test_layout.py).

    frame.py       the world's axes (Blender's, Z up), a camera's look frame, turns about Z, and the
                   latitude-longitude convention every light map is in
    camera.py      the photo camera: its frame (yaw 90: looking along +Y, the light map's azimuth 0),
                   default pitch and field of view, its height above the floor, a Blender camera's pose
    floor.py       where a pixel's ray meets the floor; the fallback room the light stage splats into
    placement.py   the user's placement (--at, --object-size) and its defaults, one for every entry point
    asset_pose.py  where the asset stands in the photo's world (core's model: the asset placed in front of
                   the camera) and the same arrangement from Blender's side (the camera placed around an
                   unmoved asset): one similarity, two directions
    mattes.py      the one compositing rule and the paper's shadow matte
"""
