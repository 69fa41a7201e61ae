"""Light estimation: LDR panorama from the photo, HDR light scales with the white-sphere apparatus.

Public entry points: `estimate_light`, `LightConfig`, `write_light_outputs`, `light_report` (estimate.py);
`ReferenceCritic` (reference_critic.py); measures in measure.py. The photo is read by core/data/photo.load_photo.
"""
from __future__ import annotations

from ...base.lazy_exports import lazy_exports

_MODULE_OF = {"LightConfig": "config", **{name: "estimate" for name in ("LightResult", "estimate_light", "light_report",
                                                                      "write_light_outputs")}}
__all__ = sorted(_MODULE_OF)
__getattr__, __dir__ = lazy_exports(__name__, globals(), _MODULE_OF)
