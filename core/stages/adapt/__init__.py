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
from .checkpoint import CHECKPOINT_FILE, load_checkpoint, save_checkpoint
from .config import (GENERATE_STAGES, MODE_SETTINGS, MODE_TYPES, SCENE_STAGES, AdaptConfig, StageSpec, edit_prompt,
                     stage_at)
from .distributed import init_distributed
from .sampling import sample_camera, sample_view, spherical_gaussian_environment, view_suffix
from .stage import adapt_and_bake, adapt_texture, write_adapt
from .stage_data import AdaptInputs, AdaptResult
from .system import AdaptSystem

__all__ = [
    "CHECKPOINT_FILE", "GENERATE_STAGES", "MODE_SETTINGS", "MODE_TYPES", "SCENE_STAGES", "AdaptConfig", "AdaptInputs",
    "AdaptResult", "AdaptSystem", "StageSpec", "adapt_and_bake", "adapt_texture", "edit_prompt", "init_distributed",
    "load_checkpoint", "sample_camera", "sample_view", "save_checkpoint", "spherical_gaussian_environment",
    "stage_at", "view_suffix", "write_adapt",
]
