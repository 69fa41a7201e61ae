"""The neural texture: UV-space position map, hash-grid + MLP appearance model, direct fit, bake.

rasterize_uv(mesh, H) -> UVRaster           the paper's position map C and coverage
NeuralTexture(config)                         3D point -> base colour, roughness, metallic
fit_direct(texture, C, mask, target, ...)     regression in texture space (asset has a UV texture)
bake_maps(texture, C, border, fill, out_dir)  PNG maps + texture.pt; load_neural_texture() resumes
"""
from .bake import bake_maps, bake_texture, load_neural_texture, save_neural_texture
from .fit_direct import FitResult, encode_for_metric, fit_direct, masked_psnr
from .hashgrid import HashGrid3D
from .neural_texture import CHANNELS, NeuralTexture, NeuralTextureConfig, TexelPlan, split_channels
from .uv_raster import UVRaster, rasterize_uv, seam_fill_index

__all__ = [
    "CHANNELS", "FitResult", "HashGrid3D", "NeuralTexture", "NeuralTextureConfig", "TexelPlan",
    "UVRaster", "bake_maps", "bake_texture", "encode_for_metric", "fit_direct", "load_neural_texture",
    "masked_psnr", "rasterize_uv", "save_neural_texture", "seam_fill_index", "split_channels",
]
