"""The adapt stage's checkpoint: texture, optimiser, ε_ψ and history, tied to the settings that made it."""
from __future__ import annotations

import io
from pathlib import Path

import torch

from ...base.atomic import write_bytes_atomic
from ...base.errors import InputError
from ...guidance.lora import LoraCritic
from ...texture.bake import torch_load_reason
from ...texture.neural_texture import NeuralTexture
from .config import AdaptConfig

CHECKPOINT_FILE = "adapt_checkpoint.pt"
CHECKPOINT_FORMAT = "scenefit.adapt_checkpoint"
# Settings that may change between a run and its resumption (batch_views: the same gradients, less memory).
RESUMABLE_FIELDS = ("checkpoint_every", "preview_every", "batch_views")


def settings_key(config: AdaptConfig) -> dict:
    d = config.to_dict()
    for name in RESUMABLE_FIELDS:
        d.pop(name, None)
    return d


def save_checkpoint(path: Path, iteration: int, config: AdaptConfig, texture: NeuralTexture, optimizer,
                    lora: LoraCritic | None, history: list[dict]) -> Path:
    payload = {
        "format": CHECKPOINT_FORMAT, "iteration": iteration, "settings": settings_key(config),
        "texture_config": texture.config.to_dict(),
        "texture": {k: v.detach().cpu() for k, v in texture.state_dict().items()},
        "optimizer": optimizer.state_dict(), "lora": None if lora is None else lora.state_dict(),
        "history": history,
    }
    buffer = io.BytesIO()
    torch.save(payload, buffer)
    return write_bytes_atomic(path, buffer.getvalue())


def load_checkpoint(path: Path, config: AdaptConfig) -> dict | None:
    """The checkpoint's payload, None when there is none; a clear error when it cannot be resumed."""
    if not path.is_file():
        return None
    try:
        # A checkpoint may come from anywhere (a colleague's folder, a batch worker): it is data, so
        # torch's restricted unpickler reads tensors and plain containers and refuses anything that
        # would run code.
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as error:
        raise InputError(f"The checkpoint '{path}' cannot be read ({torch_load_reason(error)}); delete it to start "
                         "over.") from None
    if not isinstance(payload, dict) or payload.get("format") != CHECKPOINT_FORMAT:
        raise InputError(f"'{path}' is not a SceneFit adapt checkpoint; delete it to start over.")
    if payload["settings"] != settings_key(config):
        theirs, ours = payload["settings"], settings_key(config)
        differ = sorted(k for k in set(theirs) | set(ours) if theirs.get(k) != ours.get(k))
        raise InputError(f"The checkpoint '{path}' was made with other settings ({', '.join(differ)}); "
                         f"use the same settings to resume, or delete it to start over.")
    return payload
