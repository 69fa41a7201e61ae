"""Light estimation: LDR panorama from the photo, HDR light scales with the white-sphere apparatus.

Public entry points: `estimate_light`, `LightConfig`, `write_light_outputs`, `light_report` (estimate.py);
`ReferenceCritic` (reference_critic.py); measures in measure.py. The photo is read by core/data/photo.load_photo.
"""
from .estimate import LightConfig, LightResult, estimate_light, light_report, write_light_outputs

__all__ = ["LightConfig", "LightResult", "estimate_light", "light_report", "write_light_outputs"]
