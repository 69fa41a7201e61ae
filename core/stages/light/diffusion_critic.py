"""The diffusion light critic: core/guidance's VSD ScoreCritic behind the light stage's critic interface.

    critic(renders (V, h, w, 3) linear HDR, CriticRequest) -> (V, h, w, 3) image-space gradients

Per view (appendix "Light Estimation"): the linear render is tone-mapped by the extended Reinhard
curve (the forward of the prior's inverse tone curve, so a clipped photo texel and the prior's HDR
texel look alike) and sRGB-encoded to [0, 1]. views_type "composited" (the paper's): the object and
sphere (coverage request.alphas) are alpha-blended into the photo at their place with the floor's
shadow (the paper's thresholded matte, core/stages/compose.py `paper_shadow_matte`, from the floor pixels
request.floor_alphas), by compose's linear-light rule, and the critic sees two global views: the full
scene and a crop interpolated between the full scene and the view's own square. views_type
"apparatus": the render itself, in front of the map. Each image is resized to the model's
resolution and VAE-encoded; t is drawn uniformly in request.t_range ([750, 990]); the ScoreCritic gives
∇z = w_t (ε_φ(z_t, text; CFG 7.5) - ε_ψ(z_t, text, camera)) (VSD, λ = 1), which autograd carries
back through the VAE and the tone curve to the render's pixels. ε_ψ then takes one LoRA step on the
detached latents, its learning rate annealed with the scales' (linearly to 0.1 x). ε_ψ is conditioned
on the view's camera and the current light (the appendix's c_x, c_y, c_r, c_v, b_v, taken from the
map the renders were made under: request.light, see hdr.LightVector). Text
conditioning is the prompt in the request (estimate.py's object prompt / SPHERE_PROMPT with the
dark-environment suffix and tint).
"""
from __future__ import annotations


import numpy as np
import torch
import torch.nn.functional as F

from ...base.errors import InputError
from ...guidance.critics import CriticConfig, ScoreCritic
from ...guidance.lora import AMBIENT_LIGHT, LoraCritic, camera_condition
from ...guidance.models import GuidanceModels
from ...guidance.views import linear_to_srgb_torch, paste_layer, photo_crop, srgb_to_linear_torch
from ...scene.mattes import composite_linear, paper_shadow_matte
from .hdr import DEFAULT_L_WHITE, CriticRequest
from .config import DiffusionCriticConfig

LUMINANCE = (0.2126, 0.7152, 0.0722)


def tonemap_srgb_torch(radiance: torch.Tensor, l_white: float = DEFAULT_L_WHITE) -> torch.Tensor:
    """Linear HDR -> sRGB [0, 1] by the extended Reinhard curve L (1 + L / Lw^2) / (1 + L); differentiable."""
    x = radiance.clamp_min(0.0)
    return linear_to_srgb_torch(x * (1.0 + x / (l_white * l_white)) / (1.0 + x))


class DiffusionLightCritic:
    """VSD critic for the light scales; one LoRA ε_ψ shared by every view, told apart by its camera and
    conditioned on the current light."""

    def __init__(self, models: GuidanceModels, cameras, prompts: tuple[str, ...],
                 config: DiffusionCriticConfig = DiffusionCriticConfig(), photo: np.ndarray | None = None,
                 squares: list[tuple[float, float, float]] | None = None) -> None:
        """photo (sRGB, (H, W, 3)) and squares (per view, where its square rendering goes in the photo:
        ApparatusScene.photo_squares) are needed for views_type "composited"."""
        self.size = config.model_resolution or models.image_size
        if self.size // models.vae_scale_factor < 1:
            raise InputError("model_resolution is smaller than one latent texel.")
        if config.views_type == "composited" and (photo is None or squares is None or len(squares) != len(cameras)):
            raise InputError("The composited light critic needs the photo and one square per view.")
        self.models, self.config = models, config
        self.photo = None if photo is None else np.clip(np.asarray(photo, np.float32)[..., :3], 0.0, 1.0)
        self.squares = squares
        self.cameras = [(c.origin, c.forward) for c in cameras]
        for p in tuple(prompts) + (config.negative_prompt,):
            models.embed(p)
        self.lora = LoraCritic(models.unet, rank=config.lora_rank, lr=config.lr_lora,
                               condition_dropout=config.condition_dropout, seed=config.seed)
        self.score = ScoreCritic(models.unet, models.scheduler,
                                 CriticConfig(critic_type="vsd", guidance_scale=config.guidance_scale,
                                              lambda_end=config.lambda_vsd, reference_type="none"), lora=self.lora)
        self.rng = np.random.default_rng(config.seed)
        self.generator = torch.Generator().manual_seed(config.seed)
        self.history: list[dict] = []

    def condition(self, view: int, light: tuple[float, ...] | None) -> torch.Tensor:
        """ε_ψ's class condition: the view's camera-to-world matrix and the light vector (ambient if none)."""
        origin, forward = self.cameras[view]
        return camera_condition(origin, forward, AMBIENT_LIGHT if light is None else light)

    def _anneal_lora(self, request: CriticRequest) -> None:
        n = max(request.iterations - 1, 1)
        factor = 1.0 - (1.0 - self.config.lr_lora_final_factor) * min(request.iteration, n) / n
        for group in self.lora.optimizer.param_groups:
            group["lr"] = self.config.lr_lora * factor

    def __call__(self, renders: torch.Tensor, request: CriticRequest) -> torch.Tensor:
        if len(request.prompts) != renders.shape[0]:
            raise InputError(f"The light critic got {renders.shape[0]} views and {len(request.prompts)} prompts.")
        indices = request.view_indices or tuple(range(renders.shape[0]))
        self._anneal_lora(request)
        uncond = self.models.embed(self.config.negative_prompt)
        size = self.size
        grads = []
        for i, (prompt, view) in enumerate(zip(request.prompts, indices)):
            # Gradients stop at `leaf`; each image the model sees carries its share back to it.
            leaf = renders[i].detach().to(self.models.device, torch.float32).requires_grad_(True)
            text = self.models.embed(prompt)
            condition = self.condition(view, request.light)
            with torch.enable_grad():
                images = self.views(leaf, request, i, view)
            for name, image in images.items():
                with torch.enable_grad():
                    if image.shape[-2:] != (size, size):
                        image = F.interpolate(image, size=(size, size), mode="bilinear", align_corners=False)
                    latents = self.models.encode(image)
                    # VSD at t ~ U[t_range]: ∇z = w_t (ε_φ (CFG) - ε_ψ); the view's images share its weight.
                    t = int(self.rng.integers(request.t_range[0], request.t_range[1] + 1))
                    noise = torch.randn(latents.shape, generator=self.generator).to(latents.device)
                    out = self.score(latents, t, noise, text, uncond, lam=self.config.lambda_vsd, condition=condition)
                    (out.loss / len(images)).backward(retain_graph=name != list(images)[-1])
                # ε_ψ learns the current renderings (its LoRA loss on the detached latents).
                lora_loss = self.lora.learn(latents, text, condition, self.rng, self.generator, self.score.alpha_bar,
                                            self.score.prediction_type, 1.0 / len(images))
                self.history.append({"iteration": request.iteration, "view": int(view), "image": name, "t": t,
                                     "light": request.light, "grad_norm": out.metrics["grad_norm"],
                                     "lora_loss": round(lora_loss, 6)})
            self.lora.step()
            grads.append(torch.nan_to_num(leaf.grad, nan=0.0, posinf=0.0, neginf=0.0))
        return torch.stack(grads).to(renders.device, renders.dtype)

    def global_windows(self, view: int) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        """The appendix's two global views as square windows (x0, y0, side) of the photo: one always the
        full scene (the whole photo, its short side padded by repeating the edge), one interpolated
        between the view's own square and the full scene (u ~ U[0, 1] from the critic's generator)."""
        h, w = self.photo.shape[:2]  # type: ignore[union-attr]
        full = ((w - max(h, w)) / 2, (h - max(h, w)) / 2, float(max(h, w)))
        u = float(self.rng.uniform())
        return full, tuple(a + u * (b - a) for a, b in zip(self.squares[view], full))  # type: ignore[index]

    def views(self, leaf: torch.Tensor, request: CriticRequest, i: int, view: int) -> dict[str, torch.Tensor]:
        """The (1, 3, h, w) sRGB images the model scores for one render (h, w, 3): the render itself
        ("apparatus"), or the two global views of it in the photo ("full" and "crop")."""
        display = tonemap_srgb_torch(leaf, self.config.l_white)
        if self.config.views_type == "apparatus":
            return {"apparatus": display.permute(2, 0, 1)[None]}
        if request.alphas is None or request.floor_alphas is None:
            raise InputError("The composited light critic needs the object's and the floor's coverage in the request.")
        alpha = request.alphas[i].to(leaf)
        floor = request.floor_alphas[i].to(leaf)[..., 0] > 0.5
        # The object and sphere, tone-mapped like the photo they join; the floor gives only its shadow.
        premultiplied = srgb_to_linear_torch(display) * alpha
        intensity = leaf @ torch.tensor(LUMINANCE, dtype=leaf.dtype, device=leaf.device)
        matte, *_ = paper_shadow_matte(intensity, floor, self.config.shadow_threshold)
        darkening = (1.0 - matte)[..., None].expand(*matte.shape, 3)
        layer = torch.cat([premultiplied, alpha, darkening], dim=-1)
        x0, y0, side = self.squares[view]  # type: ignore[index]
        size = self.size
        images = {}
        for name, window in zip(("full", "crop"), self.global_windows(view)):
            pasted = paste_layer(layer, (x0, y0, side, side), window, size)
            photo = torch.from_numpy(photo_crop(self.photo, window, size)).to(leaf).permute(2, 0, 1)[None]  # type: ignore[arg-type]
            linear = composite_linear(pasted[:, :3], pasted[:, 3:4], srgb_to_linear_torch(photo), 1.0 - pasted[:, 4:7])
            images[name] = linear_to_srgb_torch(linear)
        return images
