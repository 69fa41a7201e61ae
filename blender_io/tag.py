"""The custom property every datablock SceneFit makes carries (its value: the stage that made it), so
SceneFit's own objects, materials, images and Worlds are told from the artist's, which it never changes."""

TAG = "scenefit"
