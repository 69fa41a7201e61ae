"""The adapt stage's checkpoint: texture, optimiser, ε_ψ and history, tied to the settings and the inputs
(the asset's mesh, its starting texture, the photo and the light) that made it.

A checkpoint found in a folder is data from elsewhere (a planted or damaged file, another asset's run):
its shape is checked before any of it is used; one made for other inputs is not resumed (the run starts
fresh), one made with other settings is refused in one sentence."""
from __future__ import annotations

import hashlib
import io
from pathlib import Path

import numpy as np
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


def inputs_digest(*parts) -> str:
    """A digest of what a run adapts: arrays, tensors, state dicts and plain values, in order."""
    digest = hashlib.sha256()

    def add(value) -> None:
        if isinstance(value, torch.Tensor):
            value = value.detach().cpu().numpy()
        if isinstance(value, np.ndarray):
            digest.update(f"{value.dtype}{value.shape}".encode())
            digest.update(np.ascontiguousarray(value).tobytes())
        elif isinstance(value, dict):
            for key in sorted(value, key=str):
                digest.update(str(key).encode())
                add(value[key])
        elif isinstance(value, (list, tuple)):
            for item in value:
                add(item)
        else:
            digest.update(repr(value).encode())

    for part in parts:
        add(part)
    return digest.hexdigest()


def save_checkpoint(path: Path, iteration: int, config: AdaptConfig, texture: NeuralTexture, optimizer,
                    lora: LoraCritic | None, history: list[dict], inputs: str = "") -> Path:
    payload = {
        "format": CHECKPOINT_FORMAT, "iteration": iteration, "settings": settings_key(config), "inputs": inputs,
        "texture_config": texture.config.to_dict(),
        "texture": {k: v.detach().cpu() for k, v in texture.state_dict().items()},
        "optimizer": optimizer.state_dict(), "lora": None if lora is None else lora.state_dict(),
        "history": history,
    }
    buffer = io.BytesIO()
    torch.save(payload, buffer)
    return write_bytes_atomic(path, buffer.getvalue())


def load_checkpoint(path: Path, config: AdaptConfig, inputs: str = "") -> dict | None:
    """The checkpoint's payload; None when there is none or it was made for other inputs (the run starts
    fresh); one sentence when it cannot be resumed: not a checkpoint, not of the shape SceneFit writes, or
    made with other settings."""
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
    wrong = _shape_problem(payload, config)
    if wrong:
        raise InputError(f"The checkpoint '{path}' is not what SceneFit writes ({wrong}); delete it to start over.")
    if payload["settings"] != settings_key(config):
        theirs, ours = payload["settings"], settings_key(config)
        differ = sorted(k for k in set(theirs) | set(ours) if theirs.get(k) != ours.get(k))
        raise InputError(f"The checkpoint '{path}' was made with other settings ({', '.join(differ)}); "
                         f"use the same settings to resume, or delete it to start over.")
    if payload["inputs"] != inputs:   # another asset's, or this stage's before its inputs changed: not resumed
        return None                   # (the run starts fresh and its first checkpoint replaces it)
    return payload


def _shape_problem(payload: dict, config: AdaptConfig) -> str | None:
    """What in the payload is not of the shape `save_checkpoint` writes (None: it is)."""
    iteration = payload.get("iteration")
    checks = (
        ("settings", isinstance(payload.get("settings"), dict), "a table of settings"),
        ("inputs", isinstance(payload.get("inputs"), str), "the inputs' digest"),
        ("iteration", isinstance(iteration, int) and not isinstance(iteration, bool)
         and 0 <= iteration <= config.iterations, f"a whole number from 0 to {config.iterations}"),
        ("history", isinstance(payload.get("history"), list) and all(isinstance(h, dict) for h in payload["history"]),
         "a list of tables"),
        ("texture", isinstance(payload.get("texture"), dict)
         and all(isinstance(v, torch.Tensor) for v in payload["texture"].values()), "a table of tensors"),
        ("optimizer", isinstance(payload.get("optimizer"), dict), "the optimiser's state"),
        ("lora", payload.get("lora") is None or isinstance(payload.get("lora"), dict), "the LoRA's state or none"),
    )
    for key, ok, should in checks:
        if not ok:
            return f"its '{key}' is not {should}"
    return None
