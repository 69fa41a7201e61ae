"""The one place models are found and loaded: Stable Diffusion 2 base and inpainting (guidance,
outpainting) and the transformers depth estimator (the indoor panorama).

A model is a hub id (looked up in the Hugging Face cache, downloaded only when online and allowed)
or a local folder laid out like the hub repository (unet/, vae/, text_encoder/, tokenizer/,
scheduler/). `locate_models` runs before any work starts and raises ModelMissingError with the
model, where it looked and how to provide it. `load_guidance_models` then loads them with the
memory switches applied. The inpainting model shares the base model's VAE and text encoder (SD2
inpainting was fine-tuned from SD2 with both frozen), so only its UNet is loaded.
"""
from __future__ import annotations

import fnmatch
import gc
import os
from dataclasses import dataclass, field, replace
from functools import partial
from typing import Any
from pathlib import Path

import numpy as np

from ..base.errors import InputError, ModelMissingError
from .model_folder import check_model_files, check_model_memory, read_config

DEFAULT_BASE_MODEL = "stabilityai/stable-diffusion-2-base"
DEFAULT_INPAINT_MODEL = "stabilityai/stable-diffusion-2-inpainting"
DEFAULT_DEPTH_MODEL = "depth-anything/Depth-Anything-V2-Small-hf"
DEVICE_TYPES = ("auto", "cpu", "cuda", "mps")
DTYPE_TYPES = ("auto", "fp32", "fp16", "bf16")

# What each role needs from its folder (a file that must exist in each subfolder).
BASE_PARTS = {"unet": "config.json", "vae": "config.json", "text_encoder": "config.json",
              "tokenizer": None, "scheduler": "scheduler_config.json"}
INPAINT_PARTS = {"unet": "config.json"}
_WEIGHT_PATTERNS = ["*.json", "*.txt", "*.safetensors", "*.model"]
# Half-precision copies the loader never reads (it asks for no variant): a download without them is half the size.
IGNORE_PATTERNS = ["*.fp16.*"]


# The files of each part a run reads: configs, safetensors weights, the tokenizer's vocabulary.
_PART_FILES = {"unet": ("*.json", "*.safetensors"), "vae": ("*.json", "*.safetensors"),
               "text_encoder": ("*.json", "*.safetensors"), "tokenizer": ("*.json", "*.txt", "*.model"),
               "scheduler": ("*.json",)}
DEPTH_PATTERNS = ["*.json", "*.safetensors"]
# The download size of each default repository's files a run reads (the hub's listing), said before a download:
# unet 3.46 GB + text encoder 1.36 GB + VAE 0.33 GB; a UNet; one small ViT.
ABOUT_DOWNLOAD = {DEFAULT_BASE_MODEL: 5_160_000_000, DEFAULT_INPAINT_MODEL: 3_460_000_000,
                   DEFAULT_DEPTH_MODEL: 99_000_000}


def hub_patterns(parts: dict) -> list[str]:
    """The files a diffusion role's snapshot holds: its parts' configs, vocabularies and safetensors weights."""
    return [f"{sub}/{p}" for sub in parts for p in _PART_FILES.get(sub, _WEIGHT_PATTERNS)] + ["model_index.json"]


def hub_cache(cache_dir: str | None = None) -> Path:
    """The Hugging Face cache models are looked for and downloaded into: `cache_dir` when given, else the
    hub's own (HF_HUB_CACHE, else HF_HOME/hub, else ~/.cache/huggingface/hub), so weights another tool
    fetched are used where they are."""
    if cache_dir:
        return Path(cache_dir).expanduser()
    if os.environ.get("HF_HUB_CACHE"):
        return Path(os.environ["HF_HUB_CACHE"]).expanduser()
    if os.environ.get("HF_HOME"):
        return Path(os.environ["HF_HOME"]).expanduser() / "hub"
    from huggingface_hub import constants  # lazy: huggingface_hub is needed only to find or fetch models

    return Path(constants.HF_HUB_CACHE)


def hub_offline(local_files_only: bool | None = None) -> bool:
    """Whether downloads are off: asked for (local_files_only), or HF_HUB_OFFLINE=1 in the environment."""
    return bool(local_files_only) or os.environ.get("HF_HUB_OFFLINE", "").strip().lower() in ("1", "true", "yes", "on")


@dataclass(frozen=True)
class ModelConfig:
    """Which diffusion models and how to hold them in memory.

    base_model / inpaint_model: hub id or local folder. cache_dir: the Hugging Face cache to look in
    (None: HF_HUB_CACHE / HF_HOME / ~/.cache/huggingface/hub). local_files_only: never download
    (also forced by HF_HUB_OFFLINE=1). dtype_type "auto" holds the frozen weights in half precision
    where the device computes it natively: fp16 on CUDA, bf16 on a CPU with AVX512-BF16 or AMX (an
    SD2-sized UNet pass ran ~3x faster than fp32 on such a CPU, at half the memory), else fp32.
    The gradients that reach the texture, the LoRA and its optimiser stay float32.
    """

    base_model: str = DEFAULT_BASE_MODEL      # SD2 text-to-image: a hub id or a folder
    inpaint_model: str = DEFAULT_INPAINT_MODEL   # SD2 inpainting: a hub id or a folder
    cache_dir: str | None = None              # the Hugging Face cache (None: HF_HUB_CACHE / HF_HOME / ~/.cache)
    local_files_only: bool = False            # never download (also HF_HUB_OFFLINE=1)
    device_type: str = "auto"                 # auto | cpu | cuda
    dtype_type: str = "auto"                  # auto (fp16 on CUDA, bf16 where a CPU computes it) | fp32 | fp16 | bf16
    attention_slicing: bool = False           # memory switches: less memory, more time
    vae_slicing: bool = False                 # (diffusers' own switches of the same names)
    vae_tiling: bool = False                  # the VAE in tiles
    channels_last: bool = False               # the UNet in channels-last memory layout
    cpu_offload: bool = False                 # models wait on the CPU and move to the GPU when used

    def __post_init__(self) -> None:
        if self.device_type not in DEVICE_TYPES:
            raise InputError(f"device_type must be one of {DEVICE_TYPES}, got {self.device_type!r}.")
        if self.dtype_type not in DTYPE_TYPES:
            raise InputError(f"dtype_type must be one of {DTYPE_TYPES}, got {self.dtype_type!r}.")
        if not self.base_model or not self.inpaint_model:
            raise InputError("base_model and inpaint_model must name a hub id or a folder.")

    @property
    def offline(self) -> bool:
        return hub_offline(self.local_files_only)

    def device(self):
        import torch  # lazy: torch takes seconds to load

        if self.device_type == "auto":
            return torch.device(found_device())
        if self.device_type == "cuda" and not torch.cuda.is_available():
            raise InputError("device_type 'cuda' was asked for but torch sees no CUDA GPU; use 'auto' or 'cpu'.")
        if self.device_type == "mps" and not _mps_available():
            raise InputError("device_type 'mps' was asked for but torch sees no Apple GPU (MPS); use 'auto' or 'cpu'.")
        return torch.device(self.device_type)

    def dtype(self):
        import torch  # lazy: torch takes seconds to load

        if self.dtype_type == "auto":
            if self.device().type in ("cuda", "mps"):
                return torch.float16
            return torch.bfloat16 if cpu_computes_bf16() else torch.float32
        return {"fp32": torch.float32, "fp16": torch.float16, "bf16": torch.bfloat16}[self.dtype_type]


def _mps_available() -> bool:
    import torch  # lazy: torch takes seconds to load

    backend = getattr(torch.backends, "mps", None)
    return backend is not None and bool(backend.is_available())


def found_device() -> str:
    """The device "auto" means here: an NVIDIA GPU (CUDA), else an Apple GPU (MPS), else the CPU."""
    import torch  # lazy: torch takes seconds to load

    if torch.cuda.is_available():
        return "cuda"
    return "mps" if _mps_available() else "cpu"


def memory_options_for(device: str) -> tuple[str, ...]:
    """The ModelConfig memory switches that do something on `device`: slicing and tiling on any device; CPU
    offload only where the models otherwise sit in a GPU's own memory (CUDA; MPS shares the CPU's)."""
    options = ("attention_slicing", "vae_slicing", "vae_tiling")
    return options + ("cpu_offload",) if device == "cuda" else options


def cpu_computes_bf16() -> bool:
    """Whether this CPU has bf16 arithmetic (AVX512-BF16 or AMX); elsewhere torch emulates it, slower than fp32."""
    import torch  # lazy: torch takes seconds to load

    probes = [getattr(torch.cpu, name, None) for name in ("_is_avx512_bf16_supported", "_is_amx_tile_supported")]
    return any(probe is not None and bool(probe()) for probe in probes)


def _cache_dir(config: ModelConfig) -> Path:
    return hub_cache(config.cache_dir)


def is_unread_copy(name: str) -> bool:
    """A file the loader never reads (it asks for no variant): a half-precision copy (IGNORE_PATTERNS)."""
    return any(fnmatch.fnmatch(Path(name).name, pattern) for pattern in IGNORE_PATTERNS)


def _missing_parts(folder: Path, parts: dict) -> list[str]:
    """The parts of `folder` the loader would not find: no marker file, nothing at all, or (a weighted part)
    no safetensors weights but the half-precision copies it never reads."""
    missing = []
    for sub, marker in parts.items():
        path = folder / sub
        files = [p for p in path.iterdir() if not is_unread_copy(p.name)] if path.is_dir() else []
        weighted = "*.safetensors" in _PART_FILES.get(sub, ())
        if not files or (marker is not None and not (path / marker).is_file()) or \
                (weighted and not any(p.name.endswith(".safetensors") for p in files)):
            missing.append(f"{sub}/")
    return missing


# How a run goes on without the diffusion models, in each place a run is started (each a command or
# setting that exists: tests/core/guidance/test_model_hints.py parses them).
WITHOUT_GUIDANCE = ("or run without adaptation (`scenefit run --guidance-type none`, `scenefit demo --guidance none`; "
                    "in Blender, Run All with Adaptation: None)")


def locate_model(model: str, role: str, parts: dict, config: ModelConfig) -> Path:
    """The folder holding `model` (a local folder, or the hub snapshot already in the cache). Never downloads:
    only `scenefit models download` and the Preferences' Download do, when asked (core/guidance/model_store.py).

    Raises ModelMissingError naming the model, where it looked and how to provide it.
    """
    layout = ", ".join(p + "/" for p in parts)
    local = Path(model).expanduser()
    is_folder = local.is_dir() or model.startswith((".", "/", "~")) or model.count("/") > 1
    if is_folder:
        how = (f"Give a folder laid out like the hub repository ({layout}), or a hub id such as "
               f"'{DEFAULT_BASE_MODEL}'; {WITHOUT_GUIDANCE}.")
        if not local.is_dir():
            raise ModelMissingError(f"The {role} model folder '{local}' does not exist. {how}")
        missing = _missing_parts(local, parts)
        if missing:
            raise ModelMissingError(f"The {role} model folder '{local}' lacks {', '.join(missing)}. {how}")
        return local

    from huggingface_hub import snapshot_download  # lazy: huggingface_hub is needed only to find or fetch models

    cache = _cache_dir(config)
    patterns = hub_patterns(parts)
    try:
        folder = Path(snapshot_download(model, cache_dir=cache, local_files_only=True, allow_patterns=patterns,
                                        ignore_patterns=IGNORE_PATTERNS))
    except Exception:
        folder = None
    if folder is not None and not _missing_parts(folder, parts):
        return folder
    about = ABOUT_DOWNLOAD.get(model)
    size = f", about {about / 1e9:.1f} GB" if about else ""
    how = (f"Download it first (`scenefit models download`{size}, or Download in SceneFit's Preferences); "
           f"without a network, run `hf download {model}` on a machine with one and copy its cache here (or "
           f"point the cache folder setting / HF_HUB_CACHE at it); or give a local folder with {layout} as the "
           f"{role} model; {WITHOUT_GUIDANCE}.")
    raise ModelMissingError(f"The {role} model '{model}' is not in the Hugging Face cache at '{cache}'. {how}")


def locate_models(config: ModelConfig, need_inpaint: bool) -> dict[str, Path]:
    """Find every model a run needs, before any work starts: {"base": folder, "inpaint": folder}."""
    found = {"base": locate_model(config.base_model, "Stable Diffusion 2 base (local view)", BASE_PARTS, config)}
    if need_inpaint:
        found["inpaint"] = locate_model(config.inpaint_model, "Stable Diffusion 2 inpainting (global view)",
                                        INPAINT_PARTS, config)
    return found


def models_available(config: ModelConfig, need_inpaint: bool = True) -> tuple[bool, str]:
    """(True, where) when the models are already on this machine (never downloads), else (False, why)."""
    try:
        found = locate_models(replace(config, local_files_only=True), need_inpaint)
    except ModelMissingError as error:
        return False, str(error)
    return True, ", ".join(f"{k}: {v}" for k, v in found.items())


@dataclass
class GuidanceModels:
    """Loaded models. Text embeddings are computed once per prompt (`embed`), after which the text
    encoder can be released (`release_text_encoder`)."""

    tokenizer: Any
    text_encoder: Any | None
    vae: Any
    unet: Any
    scheduler: Any
    inpaint_unet: Any | None
    device: Any
    dtype: Any
    paths: dict[str, Path]
    config: ModelConfig
    _embeddings: dict[str, object] = field(default_factory=dict)

    @property
    def vae_scale_factor(self) -> int:
        return 2 ** (len(self.vae.config.block_out_channels) - 1)

    @property
    def image_size(self) -> int:
        """The image side the base model was trained at: its UNet's latent side times the VAE's downsampling
        (SD2-base 64 x 8 = 512, SD 2.1 96 x 8 = 768)."""
        return int(self.unet.config.sample_size) * self.vae_scale_factor

    @property
    def latent_scale(self) -> float:
        return float(self.vae.config.scaling_factor)

    def embed(self, prompt: str):
        """(1, 77, D) text embedding of `prompt`, cached."""
        import torch  # lazy: torch takes seconds to load

        if prompt not in self._embeddings:
            if self.text_encoder is None:
                raise RuntimeError(f"The text encoder was released before prompt {prompt!r} was embedded.")
            ids = self.tokenizer(prompt, padding="max_length", max_length=self.tokenizer.model_max_length,
                                 truncation=True, return_tensors="pt").input_ids
            encoder_device = next(self.text_encoder.parameters()).device
            with torch.no_grad():
                hidden = self.text_encoder(ids.to(encoder_device))[0]
            self._embeddings[prompt] = hidden.to(self.device, self.dtype)
        return self._embeddings[prompt]

    def encode(self, images):
        """SD latents (float32) of sRGB images (N, 3, H, W) in [0, 1]: the VAE posterior mean, scaled.
        Differentiable with respect to `images` (gradients flow back through the encoder)."""
        import torch  # lazy: torch takes seconds to load

        x = (images * 2.0 - 1.0).to(self.device, self.vae.dtype)
        if self.vae.encoder.conv_in.weight.is_contiguous(memory_format=torch.channels_last):
            x = x.contiguous(memory_format=torch.channels_last)
        return self.vae.encode(x).latent_dist.mean.float() * self.latent_scale

    def release_text_encoder(self) -> None:
        self.text_encoder = None
        _empty_cache(self.device)


def _empty_cache(device) -> None:
    import torch  # lazy: torch takes seconds to load

    gc.collect()
    if getattr(device, "type", "") == "cuda":
        torch.cuda.empty_cache()
    elif getattr(device, "type", "") == "mps":
        torch.mps.empty_cache()


def load_guidance_models(config: ModelConfig, need_inpaint: bool, paths: dict[str, Path] | None = None) -> GuidanceModels:
    """Locate (unless `paths` is given) and load the models onto the configured device and dtype."""
    # lazy: torch, diffusers and transformers take seconds to load
    import torch
    from diffusers import AutoencoderKL, DDPMScheduler, UNet2DConditionModel
    from transformers import CLIPTextModel, CLIPTokenizer

    paths = paths or locate_models(config, need_inpaint)
    device, dtype = config.device(), config.dtype()
    base = paths["base"]
    _check_guidance_folders(paths, dtype)
    tokenizer = CLIPTokenizer.from_pretrained(base, subfolder="tokenizer")
    text_encoder = CLIPTextModel.from_pretrained(base, subfolder="text_encoder", torch_dtype=dtype,
                                                 use_safetensors=True)
    vae = AutoencoderKL.from_pretrained(base, subfolder="vae", torch_dtype=dtype, use_safetensors=True)
    unet = UNet2DConditionModel.from_pretrained(base, subfolder="unet", torch_dtype=dtype, use_safetensors=True)
    # Only ᾱ_t and the prediction type are used; DDPM reads SD2's PNDM/DDIM configs too.
    scheduler = DDPMScheduler.from_pretrained(base, subfolder="scheduler")
    inpaint_unet = None
    if need_inpaint:
        inpaint_unet = UNet2DConditionModel.from_pretrained(paths["inpaint"], subfolder="unet", torch_dtype=dtype,
                                                            use_safetensors=True)
        if inpaint_unet.config.in_channels != 9:
            raise ModelMissingError(f"The inpainting model at '{paths['inpaint']}' has a UNet with "
                                    f"{inpaint_unet.config.in_channels} input channels; an inpainting UNet has 9.")
    if unet.config.in_channels != 4:
        raise ModelMissingError(f"The base model at '{base}' has a UNet with {unet.config.in_channels} input "
                                f"channels; a text-to-image UNet has 4.")
    for module in (text_encoder, vae, unet, inpaint_unet):
        if module is not None:
            module.requires_grad_(False)
            module.eval()
    unets = [u for u in (unet, inpaint_unet) if u is not None]
    if config.attention_slicing:
        for u in unets:
            u.set_attention_slice("auto")
    if config.vae_slicing:
        vae.enable_slicing()
    if config.vae_tiling:
        vae.enable_tiling()
    if config.channels_last:
        for u in unets:
            u.to(memory_format=torch.channels_last)
    if device.type == "cpu" and dtype == torch.bfloat16:
        # oneDNN's bf16 convolutions want channels-last: the SD VAE's 512-px encode + backward went
        # from 7.9 + 7.5 s to 3.3 + 5.1 s here (the UNet, at 64x64 latents, gained nothing).
        vae.to(memory_format=torch.channels_last)
    if config.cpu_offload and device.type == "cuda":
        # Each model moves to the GPU when called and the previous one goes back (accelerate hooks).
        from accelerate import cpu_offload_with_hook

        hook = None
        for module in (text_encoder, vae, *unets):
            _, hook = cpu_offload_with_hook(module, device, prev_module_hook=hook)
    else:
        for module in (text_encoder, vae, *unets):
            module.to(device)
    return GuidanceModels(tokenizer=tokenizer, text_encoder=text_encoder, vae=vae, unet=unet, scheduler=scheduler,
                          inpaint_unet=inpaint_unet, device=device, dtype=dtype, paths=paths, config=config)


def _check_guidance_folders(paths: dict[str, Path], dtype) -> None:
    """The folders' files and configs checked, and each network's size against memory, before any is loaded."""
    from diffusers import AutoencoderKL, UNet2DConditionModel   # lazy: seconds to load
    from transformers import CLIPTextConfig, CLIPTextModel   # lazy: seconds to load

    size = dtype.itemsize
    for role, folder in paths.items():
        check_model_files(folder, f"{role} model")
        unet = read_config(folder / "unet" / "config.json", f"{role} model's UNet")
        check_model_memory(partial(UNet2DConditionModel.from_config, unet), folder / "unet", f"{role} model's UNet",
                           size)
    base = paths["base"]
    vae = read_config(base / "vae" / "config.json", "base model's VAE")
    check_model_memory(lambda: AutoencoderKL.from_config(vae), base / "vae", "base model's VAE", size)
    text = read_config(base / "text_encoder" / "config.json", "base model's text encoder")
    check_model_memory(lambda: CLIPTextModel(CLIPTextConfig.from_dict(text)), base / "text_encoder",
                       "base model's text encoder", size)


class ModelCache:
    """Models loaded once per worker process and handed to job after job (batch workers, Ray actors).

    `get` returns a fresh `GuidanceModels` around the same modules, so a job that releases its
    text encoder (the adapt stage does) releases it from its own handle only: the next job still
    embeds its prompts. LoRA adapters and attention processors are reset by each run that sets them.
    """

    def __init__(self) -> None:
        self._loaded: dict[tuple, GuidanceModels] = {}
        self.loads = 0

    def get(self, config: ModelConfig, need_inpaint: bool) -> GuidanceModels:
        key = (config, need_inpaint)
        if key not in self._loaded:
            # A model set with the inpainting UNet also serves jobs that do not need it.
            wider = self._loaded.get((config, True))
            if wider is None:
                self._loaded[key] = load_guidance_models(config, need_inpaint)
                self.loads += 1
            else:
                key = (config, True)
        cached = self._loaded[key]
        return replace(cached, _embeddings=dict(cached._embeddings))


# -- the depth estimator (transformers) ------------------------------------------------------------

class DepthEstimator:
    """A loaded transformers depth estimator: `predict(photo_srgb) -> (h, w) raw prediction`.

    kind: "disparity" (relative models, inverse depth up to a scale) or "depth" (metric ones)."""

    def __init__(self, model: str, cache_dir: str | None = None, local_files_only: bool | None = None,
                 device: str = "cpu") -> None:
        # lazy: transformers takes seconds to load
        from transformers import AutoImageProcessor, AutoModelForDepthEstimation

        local = Path(model).expanduser()
        try:
            if local.exists() or model.startswith((".", "/", "~")):
                source = str(local)
            else:
                # lazy: huggingface_hub is needed only to find or fetch models
                from huggingface_hub import snapshot_download

                # The cache alone (a download is asked for: `scenefit models download depth`, Preferences'
                # Download); transformers' own loading retries each file's request and took 100 s to give up.
                source = snapshot_download(model, cache_dir=hub_cache(cache_dir), local_files_only=True,
                                           allow_patterns=DEPTH_PATTERNS, ignore_patterns=IGNORE_PATTERNS)
            _check_depth_folder(Path(source))
            self.processor = AutoImageProcessor.from_pretrained(source, local_files_only=True)
            self.model = AutoModelForDepthEstimation.from_pretrained(source, local_files_only=True,
                                                                     use_safetensors=True)
        except (OSError, ValueError) as error:
            raise ModelMissingError(
                f"The depth model '{model}' was not found in {_where_looked(model, cache_dir)}. Download it first "
                f"(`scenefit models download depth`, or Download in SceneFit's Preferences; without a network, "
                f"`hf download {model}` on a machine with one, into that cache), or pass a local folder "
                f"holding config.json, the weights and preprocessor_config.json (--depth-model PATH); or use "
                f"the geometric fallback (--depth geometric). Cause: {_first_sentence(error)}") from error
        self.model.eval().to(device)
        self.device = device
        self.name = model
        kind = getattr(self.model.config, "depth_estimation_type", None)
        self.kind = "depth" if kind == "metric" or "zoedepth" in self.model.config.model_type else "disparity"

    def predict(self, photo_srgb):
        """Raw prediction resized to the photo: disparity (relative models) or depth (metric ones)."""
        # lazy: torch takes seconds to load
        import torch
        import torch.nn.functional as F

        image = np.clip(np.round(photo_srgb[..., :3] * 255.0), 0, 255).astype(np.uint8)
        inputs = self.processor(images=image, return_tensors="pt")
        with torch.no_grad():
            pred = self.model(**{k: v.to(self.device) for k, v in inputs.items()}).predicted_depth
        pred = F.interpolate(pred[:, None].float(), size=image.shape[:2], mode="bilinear", align_corners=False)
        return pred[0, 0].cpu().numpy().astype(np.float32)


def _check_depth_folder(folder: Path) -> None:
    """The depth model's files and config checked, and its size against memory, before transformers reads it."""
    if not folder.is_dir():
        return   # transformers' own error says what is missing
    from transformers import AutoConfig, AutoModelForDepthEstimation   # lazy: seconds to load

    check_model_files(folder, "depth model")
    if (folder / "config.json").is_file():
        read_config(folder / "config.json", "depth model")
        check_model_memory(lambda: AutoModelForDepthEstimation.from_config(AutoConfig.from_pretrained(folder)),
                           folder, "depth model", 4)


def _first_sentence(error: Exception) -> str:
    """The library's own reason, without its advice to the library's users (URLs, local directories)."""
    lines = str(error).strip().splitlines()
    return (lines[0].split(". ")[0] if lines else type(error).__name__)[:200]


def _where_looked(model: str, cache_dir: str | None) -> str:
    if Path(model).expanduser().exists() or model.startswith((".", "/", "~")):
        return f"the folder {Path(model).expanduser()}"
    return f"the Hugging Face cache {hub_cache(cache_dir)}"


_DEPTH_CACHE: dict[tuple, DepthEstimator] = {}


def load_depth_estimator(model: str, cache_dir: str | None = None, local_files_only: bool | None = None,
                         device: str = "cpu") -> DepthEstimator:
    """The depth estimator `model` (hub id or folder), loaded once per process."""
    key = (model, cache_dir, hub_offline(local_files_only), device)
    if key not in _DEPTH_CACHE:
        _DEPTH_CACHE[key] = DepthEstimator(model, cache_dir, local_files_only, device)
    return _DEPTH_CACHE[key]

