"""The neural texture: hash-grid + MLP appearance model, direct fit, bake (its UV-space position map C is
core/data/uv_raster.py).

NeuralTexture(config)                         3D point -> base colour, roughness, metallic
fit_direct.fit_direct(texture, C, mask, ...)  regression in texture space (asset has a UV texture)
bake_maps(texture, C, border, fill, out_dir)  PNG maps + texture.pt; load_neural_texture() resumes

Each name is imported from its module when first asked for, so a module that needs one light part
(hence `scenefit --help` and the refusals the command line makes before any work) does not wait the
~2 s that importing torch takes. The function
fit_direct is imported from its module of the same name: once that module is loaded, the package's
attribute `fit_direct` is the module (Python sets it), so the package cannot hand out the function.
"""
from __future__ import annotations

from ..base.lazy_exports import lazy_exports

_MODULE_OF = {
    "bake_maps": "bake", "bake_texture": "bake", "load_neural_texture": "bake", "save_neural_texture": "bake",
    "FitResult": "fit_direct", "encode_for_metric": "fit_direct", "masked_psnr": "fit_direct",
    "HashGrid3D": "hashgrid",
    "CHANNELS": "neural_texture", "NeuralTexture": "neural_texture", "NeuralTextureConfig": "texture_config",
    "TexelPlan": "neural_texture", "split_channels": "neural_texture",
}
__all__ = sorted(_MODULE_OF)
__getattr__, __dir__ = lazy_exports(__name__, globals(), _MODULE_OF)
