"""The adapt stage: a neural texture restyled by diffusion critics (paper §3.1, §3.3, appendix).

Modes (`mode_type`):
- "scene": the paper's scene-conditional adaptation, complete setup (m): the local view (object on
  solid colours, vanilla SD with reference feature injection, VSD) and the global views (the
  compose stage's composite of the asset and its shadow in the photo, crops at several scales, SD
  inpainting), weighed equally. Starts from the converted texture.
- "generate": scene-agnostic texture generation from a prompt (setup (a)): fresh texture, no
  reference, 72-view camera sampling over elevations {20, 30, 45}, λ_FOV in [0.6, 1.21],
  view-dependent prompts, optional random spherical-Gaussian lights, coarse-to-fine stages.
- "edit": scene-agnostic editing from an instruction (setup (c)): the object prompt and the
  instruction combined into one description, reference feature injection, local views only.

config.py       AdaptConfig and StageSpec (paper defaults), the modes' settings, the stage schedule
sampling.py     every random choice of one view of one step
global_views.py the asset rendered through the photo camera where compose places it, and its shadow
stage_data.py   AdaptInputs, AdaptResult: what the stage works on and gives back
assembly.py     what AdaptSystem.build puts together: the working texture, the critics, the photo's scene
system.py       AdaptSystem: build / step / finish
metrics.py      seconds per phase, the history's entries, peak memory, when a preview goes out
stage.py        adapt_texture (the stage's run), write_adapt, and adapt_and_bake (both, the asset's UVs
                checked first)
checkpoint.py   save and resume
distributed.py  torch.distributed: views spread over ranks, gradients summed
"""
from __future__ import annotations

from ...base.lazy_exports import lazy_exports

_MODULE_OF = {
    **{name: "checkpoint" for name in ("CHECKPOINT_FILE", "load_checkpoint", "save_checkpoint")},
    **{name: "config" for name in ("GENERATE_STAGES", "MODE_SETTINGS", "MODE_TYPES", "SCENE_STAGES", "AdaptConfig",
                                   "StageSpec", "edit_prompt", "stage_at")},
    "init_distributed": "distributed",
    **{name: "sampling" for name in ("sample_camera", "sample_view", "spherical_gaussian_environment", "view_suffix")},
    **{name: "stage" for name in ("adapt_and_bake", "adapt_texture", "write_adapt")},
    **{name: "stage_data" for name in ("AdaptInputs", "AdaptResult")},
    "AdaptSystem": "system",
}
__all__ = sorted(_MODULE_OF)
__getattr__, __dir__ = lazy_exports(__name__, globals(), _MODULE_OF)
