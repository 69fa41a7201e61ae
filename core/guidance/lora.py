"""ε_ψ: a LoRA-tuned copy of the base UNet, trained online on the rendered latents (VSD).

The LoRA weights live as a peft adapter on the base UNet itself; ε_φ runs with the adapter
disabled, ε_ψ with it enabled, so the base weights are held once. ε_ψ is also conditioned on the
camera extrinsics (4x4, flattened) concatenated with the light vector (5 numbers, the appendix's
c_x, c_y, c_r, c_v, b_v) through a class embedding added to the timestep embedding; its last layer
starts at zero, so ε_ψ starts equal to ε_φ. The condition is dropped (zeroed) with probability
`condition_dropout` while training, which gives ε_ψ its own classifier-free guidance.
"""
from __future__ import annotations

from contextlib import contextmanager

import numpy as np
import torch

from ..scene.frame import look_frame
from .weighting import add_noise

ADAPTER = "scenefit_vsd"
LIGHT_DIM = 5
CONDITION_DIM = 16 + LIGHT_DIM
TARGET_MODULES = ["to_q", "to_k", "to_v", "to_out.0"]
# The appendix's default ambient light as a light vector: c_x = 0.25, c_y = 0, c_r = 0, c_v = 1, b_v = 1.
AMBIENT_LIGHT = (0.25, 0.0, 0.0, 1.0, 1.0)


def camera_condition(origin, forward, light=AMBIENT_LIGHT) -> torch.Tensor:
    """(CONDITION_DIM,) float32: the camera-to-world matrix (Z up) flattened, then the light vector."""
    f, right, up = look_frame(forward)
    c2w = np.eye(4)
    c2w[:3, 0], c2w[:3, 1], c2w[:3, 2], c2w[:3, 3] = right, up, -f, np.asarray(origin, np.float64)
    return torch.tensor(np.concatenate([c2w.ravel(), np.asarray(light, np.float64)]), dtype=torch.float32)


class LoraCritic:
    """Owns the adapter, the camera embedding and their optimiser."""

    def __init__(self, unet, rank: int = 4, lr: float = 1e-4, condition_dropout: float = 0.1, seed: int = 0) -> None:
        # lazy: diffusers and peft take seconds to load
        from diffusers.models.embeddings import TimestepEmbedding
        from peft import LoraConfig

        self.unet = unet
        self.condition_dropout = condition_dropout
        generator = torch.Generator().manual_seed(seed)
        if ADAPTER in (getattr(unet, "peft_config", None) or {}):
            unet.delete_adapters(ADAPTER)  # a fresh ε_ψ for every run
        # Seeded initialisation: peft draws lora_A from torch's global generator.
        state = torch.random.get_rng_state()
        torch.manual_seed(seed)
        unet.add_adapter(LoraConfig(r=rank, lora_alpha=rank, target_modules=TARGET_MODULES,
                                    init_lora_weights=True), adapter_name=ADAPTER)
        torch.random.set_rng_state(state)
        device = next(unet.parameters()).device
        time_dim = unet.time_embedding.linear_2.out_features
        self.embedding = TimestepEmbedding(CONDITION_DIM, time_dim)
        with torch.no_grad():
            torch.nn.init.normal_(self.embedding.linear_1.weight, std=CONDITION_DIM ** -0.5, generator=generator)
            self.embedding.linear_1.bias.zero_()
            self.embedding.linear_2.weight.zero_()   # ε_ψ = ε_φ at the start
            self.embedding.linear_2.bias.zero_()
        # LoRA and the embedding train in float32 even when the UNet runs in fp16.
        self.embedding.to(device=device, dtype=torch.float32)
        for p in self.lora_parameters():
            p.data = p.data.float()
            p.requires_grad_(True)
        unet.disable_adapters()
        self.optimizer = torch.optim.AdamW(self.parameters(), lr=lr, weight_decay=0.0)

    def lora_parameters(self) -> list[torch.nn.Parameter]:
        return [p for n, p in self.unet.named_parameters() if "lora_" in n and ADAPTER in n]

    def parameters(self) -> list[torch.nn.Parameter]:
        return self.lora_parameters() + list(self.embedding.parameters())

    @contextmanager
    def active(self):
        """ε_ψ inside, ε_φ outside."""
        unet = self.unet
        dtype = unet.dtype

        class _Embed(torch.nn.Module):  # the class embedding in the UNet's dtype
            def __init__(self, inner):
                super().__init__()
                self.inner = inner

            def forward(self, x):
                return self.inner(x.float()).to(dtype)

        unet.enable_adapters()
        for p in self.lora_parameters():  # peft's enable/disable also toggles requires_grad
            p.requires_grad_(True)
        previous = unet.class_embedding
        unet.class_embedding = _Embed(self.embedding)
        try:
            yield
        finally:
            unet.class_embedding = previous
            unet.disable_adapters()

    def state_dict(self) -> dict:
        return {"lora": {n: p.detach().cpu().clone() for n, p in self.unet.named_parameters()
                         if "lora_" in n and ADAPTER in n},
                "embedding": {k: v.detach().cpu().clone() for k, v in self.embedding.state_dict().items()},
                "optimizer": self.optimizer.state_dict()}

    def load_state_dict(self, state: dict) -> None:
        params = dict(self.unet.named_parameters())
        with torch.no_grad():
            for n, v in state["lora"].items():
                params[n].copy_(v)
        self.embedding.load_state_dict(state["embedding"])
        self.optimizer.load_state_dict(state["optimizer"])

    def train_step(self, latents: torch.Tensor, text_embedding: torch.Tensor, condition: torch.Tensor,
                   t: int, noise: torch.Tensor, alpha_bar_t: float, drop_condition: bool,
                   prediction_type: str = "epsilon", weight: float = 1.0) -> float:
        """Add the gradient of `weight` x the diffusion loss on detached rendered latents; returns the loss.

        ε_ψ learns the distribution of the current renderings (ProlificDreamer's LoRA update).
        Gradients accumulate over calls (one per view) until `step` applies and clears them.
        """
        b = latents.shape[0]   # one image's loss: the mean over its rows
        losses = self.train_rows(latents, text_embedding, condition[None].expand(b, -1), [t] * b, noise,
                                 [alpha_bar_t] * b, [drop_condition] * b, prediction_type, [weight / b] * b)
        return float(sum(losses) / b)

    def train_rows(self, latents: torch.Tensor, text_embedding: torch.Tensor, conditions: torch.Tensor,
                   timesteps: list[int], noise: torch.Tensor, alpha_bars: list[float], drops: list[bool],
                   prediction_type: str = "epsilon", weights: list[float] | None = None) -> list[float]:
        """`train_step` for B images in one UNet pass: row i with its own text (or one for all), condition
        (B, D), timestep, noise, ᾱ, dropped condition and weight; the gradient is the sum of each row's
        `weight` x its mean squared error. Returns each row's loss."""
        latents = latents.detach()
        b = latents.shape[0]
        weights = [1.0] * b if weights is None else weights
        keep = torch.tensor([0.0 if d else 1.0 for d in drops], dtype=conditions.dtype, device=conditions.device)
        cond = conditions * keep[:, None]
        x_t = torch.cat([add_noise(latents[i:i + 1], noise[i:i + 1], alpha_bars[i]) for i in range(b)])
        steps = torch.tensor(timesteps, device=latents.device, dtype=torch.long)
        # The UNet may run in fp16 (the CUDA default) while renders and latents stay float32.
        dtype = self.unet.dtype
        with self.active(), torch.enable_grad():
            text = text_embedding.to(dtype)
            pred = self.unet(x_t.to(dtype), steps, encoder_hidden_states=text.expand(b, -1, -1) if text.shape[0] == 1
                             else text, class_labels=cond.to(latents.device, dtype)).sample
            a = torch.tensor(alpha_bars, dtype=torch.float64).view(-1, 1, 1, 1)
            if prediction_type == "v_prediction":
                target = a.sqrt().float().to(latents.device) * noise.float() \
                    - (1 - a).sqrt().float().to(latents.device) * latents.float()
            else:
                target = noise.float()
            per_row = (pred.float() - target).pow(2).flatten(1).mean(dim=1)
            # Inside `active()`: leaving it turns requires_grad off, and autograd skips such leaves.
            (per_row * torch.tensor(weights, dtype=per_row.dtype, device=per_row.device)).sum().backward()
        return [float(v) for v in per_row.detach()]

    def learn(self, latents: torch.Tensor, text_embedding: torch.Tensor, condition: torch.Tensor,
              rng: np.random.Generator, generator: torch.Generator, alpha_bar: torch.Tensor,
              prediction_type: str = "epsilon", weight: float = 1.0) -> float:
        """One view's share of ε_ψ's update: t ~ U[0, T), fresh noise, the condition dropped with
        probability `condition_dropout`, all drawn from the caller's generators (so a resumed run
        repeats them); then `train_step`. Call `step` once the views (and ranks) are in."""
        return self.learn_rows(latents, text_embedding, condition[None], [rng], [generator], alpha_bar,
                               prediction_type, [weight])[0]

    def learn_rows(self, latents: torch.Tensor, text_embedding: torch.Tensor, conditions: torch.Tensor,
                   rngs: list[np.random.Generator], generators: list[torch.Generator], alpha_bar: torch.Tensor,
                   prediction_type: str = "epsilon", weights: list[float] | None = None) -> list[float]:
        """`learn` for B views in one UNet pass: row i's t, noise and dropout drawn from its own view's
        generators, exactly as `learn` draws them for that view alone."""
        ts, noise, drops = [], [], []
        for i, (rng, generator) in enumerate(zip(rngs, generators)):
            ts.append(int(rng.integers(0, len(alpha_bar))))
            noise.append(torch.randn(latents[i:i + 1].shape, generator=generator).to(latents.device))
            drops.append(bool(rng.uniform() < self.condition_dropout))
        return self.train_rows(latents, text_embedding, conditions, ts, torch.cat(noise), [float(alpha_bar[t]) for t in ts],
                               drops, prediction_type, weights)

    def step(self) -> None:
        """Apply the accumulated gradients (after an all-reduce across ranks, if any), then clear them."""
        for p in self.parameters():
            if p.grad is not None:
                p.grad.nan_to_num_(0.0, 0.0, 0.0)
        self.optimizer.step()
        self.optimizer.zero_grad(set_to_none=True)
