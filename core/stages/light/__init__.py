"""Light estimation: LDR panorama from the photo, HDR light scales with the white-sphere apparatus.

Public entry points: `estimate_light`, `LightConfig`, `load_photo`,
`write_light_outputs`, `light_report` (estimate.py); `ReferenceCritic` (reference_critic.py);
measures in measure.py.
"""
from .estimate import (LightConfig, LightResult, estimate_light, light_report,
                       load_photo, write_light_outputs)

__all__ = ["LightConfig", "LightResult", "estimate_light", "light_report",
           "load_photo", "write_light_outputs"]
