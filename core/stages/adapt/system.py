"""The adapt stage as a small system: build (models, texture, renderer, critics, resume), step (one
optimisation step over `views_per_step` views), finish (the result and its decisions).

One view of a step (core/stages/adapt/sampling.py draws its camera, light, background, t and noise; scene
and edit modes pick it from a fixed bank whose constant work, core/stages/adapt/constants.py, is done once):
  render the texture (Mitsuba, differentiable) -> local view (object on a solid colour) and global
  views (the asset rendered through the photo camera where compose places it, with compose's shadow
  matte and compositing rule, crops at several scales; core/stages/adapt/global_views.py) -> VAE
  encode -> critic (UNet passes; local and global weighed equally) -> backward through the VAE -> then
  backward through the renderer into the texture, scaled by 1 / views_per_step -> ε_ψ's LoRA loss on
  the local latents (same weight).
The step's views go through each model together (`train_views`: one VAE pass for the local images, one
for the crops, one UNet pass per critic, one ε_ψ update) where their renders can all wait for one
backward (the loop renderer's); with path tracing each view is rendered, scored and back-propagated
in turn (Mitsuba replays a render from the scene's current state), its crops still in one pass.
`AdaptConfig.batch_views` False passes one image at a time (one encoder graph held at a time: least memory).
After the step's views (and the ranks' shares, summed by torch.distributed): one Adam step on the
texture and one on ε_ψ.
"""
from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from ...base.decision import Decision
from ...base.errors import InputError
from ...base.progress import ProgressCallback, check_cancel, emit
from ...guidance.critics import gradient_loss
from ...guidance.lora import camera_condition
from ...guidance.models import GuidanceModels, load_guidance_models, locate_models
from ...guidance.views import global_view, local_view
from ...render.loop_renderer import LoopRenderer, asset_renderer
from ...render.renderer import AssetRenderer, SceneOptions
from ...texture.neural_texture import NeuralTexture, split_channels
from .assembly import Critics, build_critics, embed_prompts, global_scene_for, renderer_environment, working_texture
from .checkpoint import CHECKPOINT_FILE, inputs_digest, load_checkpoint, save_checkpoint
from .config import AdaptConfig
from .constants import ConstantWork, ViewConstants, bank_box
from .distributed import join_process_group, sum_gradients, views_of_rank
from .global_views import GlobalRender
from .metrics import PhaseTimer, mean_metrics, peak_memory_mb, preview_due
from .sampling import ViewSample, draw_view_bank, sample_view, uses_view_bank
from .stage_data import AdaptInputs, AdaptResult


def cancel_hooks(models: GuidanceModels, cancel: threading.Event) -> list:
    """Forward pre-hooks on every block of the UNets and the VAE that raise Cancelled once `cancel` is set, so
    a cancel is seen within one block's time rather than one whole view's; the caller removes them."""
    blocks: list = []
    for unet in (models.unet, models.inpaint_unet):
        if unet is not None and hasattr(unet, "down_blocks"):
            blocks += [*unet.down_blocks, unet.mid_block, *unet.up_blocks]
    vae = models.vae
    for coder, part in ((getattr(vae, "encoder", None), "down_blocks"), (getattr(vae, "decoder", None), "up_blocks")):
        blocks += list(getattr(coder, part, None) or ())
    return [block.register_forward_pre_hook(lambda module, args: check_cancel(cancel))
            for block in blocks if block is not None and hasattr(block, "register_forward_pre_hook")]


class AdaptSystem:
    """Holds everything a step needs; built once by `build`, stepped, then `finish`ed."""

    def __init__(self, inputs: AdaptInputs, config: AdaptConfig, models: GuidanceModels, texture: NeuralTexture,
                 renderer: AssetRenderer, critics: Critics, rank: int, world: Decision,
                 checkpoint_path: Path | None, cache_constants: bool = True) -> None:
        self.inputs, self.config, self.models = inputs, config, models
        self.texture, self.renderer, self.critics = texture, renderer, critics
        self._path_renderer: AssetRenderer | None = None
        self.rank, self.world = rank, world
        self.device = models.device
        raster = inputs.raster
        self.plan = texture.plan(raster.position, raster.border, raster.fill_index)
        self.base_logit = None if inputs.base_logit is None else inputs.base_logit.to(self.device)
        with torch.no_grad():  # the starting texture: the reference, and the global views' fixed coverage
            self.start_stack = texture.texture_from_plan(self.plan, self.base_logit).detach()
        self.reference_stack = self.start_stack if config.uses_reference else None
        self.base_env = torch.from_numpy(np.ascontiguousarray(renderer_environment(inputs, config)))
        self.photo = None if inputs.photo is None else np.clip(np.asarray(inputs.photo, np.float32), 0.0, 1.0)
        self.global_scene = None
        if config.views_type == "local+global":
            assert self.photo is not None   # (AdaptInputs refuses global views without the photo)
            self.global_scene = global_scene_for(inputs, config, self.photo, np.asarray(self.base_env))
        self.model_resolution = config.model_resolution or models.image_size
        self.latent_res = self.model_resolution // models.vae_scale_factor
        self.bank = draw_view_bank(config, *bank_box(self)) if uses_view_bank(config) else None
        self.constants = ConstantWork(self, cache_constants)
        # The step's images through each model in one pass (else one image at a time: less memory).
        self.batch_views = config.batch_views
        self.batched_steps = 0
        self.uncond = models.embed(config.negative_prompt)
        self.optimizer = torch.optim.Adam(texture.parameters(), lr=config.lr_texture)
        self.my_views = views_of_rank(config.views_per_step, rank, world.choice)
        self.checkpoint_path = checkpoint_path
        self._inputs_digest: str | None = None
        self.cancel: threading.Event | None = None   # seen between views (one rank), set by step
        self.history: list[dict] = []
        self.start = 0
        self.last_image: torch.Tensor | None = None
        self.last_preview = time.monotonic()
        self.timer = PhaseTimer(self.device)
        self.started = time.perf_counter()

    # -- build -------------------------------------------------------------------------------------

    @classmethod
    def build(cls, inputs: AdaptInputs, config: AdaptConfig, models: GuidanceModels | None = None,
              checkpoint_dir: str | Path | None = None, cache_constants: bool = True) -> "AdaptSystem":
        """Validate, find and load the models (a missing one fails here, before any work), copy the
        texture, set up the renderer and critics, and resume from `checkpoint_dir` when it holds one.
        cache_constants False recomputes each view's constant work every step (for comparison)."""
        inputs.validate(config)
        # Join torchrun's group first: it picks this rank's GPU, where the models must then go.
        rank, _, world = join_process_group()
        need_inpaint = config.views_type == "local+global"
        if models is None:
            paths = locate_models(config.models, need_inpaint)
            models = load_guidance_models(config.models, need_inpaint, paths)
        elif need_inpaint and models.inpaint_unet is None:
            raise InputError("Global views need the inpainting model; load the models with need_inpaint=True.")
        embed_prompts(models, config)
        texture = working_texture(inputs, config).to(models.device)
        resolution = inputs.raster.resolution[0]
        renderer = asset_renderer(config.renderer_of("local"), inputs.mesh, (resolution, resolution),
                                  renderer_environment(inputs, config),
                                  SceneOptions(max_depth=config.max_depth, hide_emitters=True))
        checkpoint_path = Path(checkpoint_dir) / CHECKPOINT_FILE if checkpoint_dir is not None else None
        system = cls(inputs, config, models, texture, renderer, build_critics(models, config), rank,
                     world, checkpoint_path, cache_constants)
        system.resume()
        if models.device.type == "cuda":
            torch.cuda.reset_peak_memory_stats()
        return system

    @property
    def inputs_digest(self) -> str:
        """What this run adapts (the checkpoint is tied to it): the mesh, the starting texture, the photo and
        where the asset stands in it, the light."""
        if self._inputs_digest is None:
            inputs = self.inputs
            mesh = inputs.mesh
            self._inputs_digest = inputs_digest(
                mesh.positions, mesh.faces, mesh.uvs, mesh.material_index, mesh.wraps,
                None if inputs.texture is None else inputs.texture.state_dict(), inputs.photo, inputs.placement,
                inputs.envmap, inputs.photo_camera, inputs.base_logit)
        return self._inputs_digest

    def resume(self) -> None:
        payload = load_checkpoint(self.checkpoint_path, self.config, self.inputs_digest) \
            if self.checkpoint_path is not None else None
        if payload is None:
            return
        try:
            self.texture.load_state_dict(payload["texture"])
            self.optimizer.load_state_dict(payload["optimizer"])
            if self.critics.lora is not None and payload["lora"] is not None:
                self.critics.lora.load_state_dict(payload["lora"])
        except (RuntimeError, ValueError, KeyError, TypeError) as error:   # shapes or keys not this run's
            reason = str(error).strip().splitlines()[0][:160] if str(error).strip() else type(error).__name__
            raise InputError(f"The checkpoint '{self.checkpoint_path}' does not fit this run's texture or "
                             f"optimiser ({reason}); delete it to start over.") from None
        self.history, self.start = list(payload["history"]), int(payload["iteration"])

    # -- step --------------------------------------------------------------------------------------

    def step(self, iteration: int, cancel: threading.Event | None = None) -> dict:
        """One optimisation step: this rank's views, gradients summed over ranks, Adam on texture and ε_ψ.
        Alone (one rank), a cancel is seen between views, so a step on a CPU stops within seconds; the
        half-made step is dropped (the texture and optimiser change only at its end). Inside a view, each
        UNet and VAE block checks it too (a pass takes tens of seconds on a CPU)."""
        self.cancel = cancel if self.world.choice == 1 else None   # (ranks must finish a step together)
        hooks = cancel_hooks(self.models, self.cancel) if self.cancel is not None else []
        try:
            return self._step(iteration)
        finally:
            for hook in hooks:
                hook.remove()

    def _step(self, iteration: int) -> dict:
        self.timer.restart()
        self.optimizer.zero_grad(set_to_none=True)
        views = [self.sample(iteration, j) for j in self.my_views]
        if self.batch_views and self.holds_renders(views):
            per_view = self.train_views(views)
            self.batched_steps += 1
        else:
            per_view = []
            for view in views:
                check_cancel(self.cancel)
                per_view.append(self.train_view(view))
        params = list(self.texture.parameters())
        for p in params:
            if p.grad is not None:
                p.grad.nan_to_num_(0.0, 0.0, 0.0)
        sum_gradients(params)
        self.optimizer.step()
        if self.critics.lora is not None:
            sum_gradients(self.critics.lora.parameters())
            self.critics.lora.step()
        self.timer.lap("step")
        metrics = mean_metrics(per_view)
        self.history.append(metrics)
        return metrics

    def sample(self, iteration: int, index: int) -> ViewSample:
        return sample_view(self.config, iteration, index, self.latent_res, self.inputs.envmap, *bank_box(self),
                           self.bank)

    def holds_renders(self, views: list[ViewSample]) -> bool:
        """Whether the views' renders can all wait for one backward: the loop renderer's can (a torch
        graph each); Mitsuba's path tracing replays a render from the scene's current state, so its
        render must be back-propagated before the scene renders the next view."""
        glob = self.global_scene.renderer if self.global_scene is not None else None
        return len(views) > 1 and all(isinstance(self.renderer_for(v), LoopRenderer) for v in views) and (
            not any(v.crops for v in views) or isinstance(glob, LoopRenderer))

    def renderer_for(self, view: ViewSample):
        """The configured renderer; path tracing for a view with its own random light under the loop
        renderer (its G-buffer would serve one step only)."""
        if view.envmap is None or not isinstance(self.renderer, LoopRenderer):
            return self.renderer
        if self._path_renderer is None:
            self._path_renderer = AssetRenderer(self.inputs.mesh, self.renderer.maps_shape,
                                                np.asarray(self.base_env), self.renderer.tracer.options)
        return self._path_renderer

    def train_view(self, view: ViewSample) -> dict:
        """Render, score and back-propagate one view (its loss weighted 1 / views_per_step); returns its metrics."""
        item = self.render_view(view)
        check_cancel(self.cancel)   # between the render and the critics (the view's heaviest half)
        return self._score([item])[0]

    def train_views(self, views: list[ViewSample]) -> list[dict]:
        """`train_view` for several views, each model run once on all of them: the texture once, each view
        rendered, then one VAE pass, one UNet pass per critic and one ε_ψ update over all their images;
        the gradients are the sum of each view's alone (to float rounding)."""
        maps = split_channels(self.texture.texture_from_plan(self.plan, self.base_logit))
        self.timer.lap("render")   # (the texture, as one view's render is charged with it)
        items = []
        for view in views:
            check_cancel(self.cancel)
            items.append(self.render_view(view, maps))
        check_cancel(self.cancel)
        return self._score(items)

    def render_view(self, view: ViewSample, maps: tuple[torch.Tensor, torch.Tensor, torch.Tensor] | None = None
                    ) -> "_Rendered":
        """The view's constant work and its renders (local, and the asset in the photo when it has crops),
        from `maps` (the step's texture) or the texture made afresh."""
        env = self.base_env if view.envmap is None else torch.from_numpy(view.envmap)
        traced = self._trace_seconds()
        constants = self.constants.get(view, env)
        self.timer.lap("constants")
        traced = self._charge_trace("constants", traced)   # the reference render may trace the view first
        if maps is None:
            maps = split_channels(self.texture.texture_from_plan(self.plan, self.base_logit))
        out = self.renderer_for(view).render(view.camera, *maps, env, spp=view.stage.spp, seed=view.render_seed)
        rendered = [torch.cat([out.rgb, out.alpha], dim=-1)]
        placed = None
        if view.crops:
            assert self.global_scene is not None   # (crops are drawn only for global views)
            placed = self.global_scene.render(*maps, env, view.camera.azimuth_deg, view.stage.render_size,
                                              view.stage.spp, view.render_seed + 1)
            rendered.append(torch.cat([placed.rgb, placed.alpha], dim=-1))
        self.timer.lap("render")
        self._charge_trace("render", traced)
        # Gradients stop at the leaves, so the two halves of backward can be timed.
        leaves = [r.detach().to(self.device).requires_grad_(True) for r in rendered]
        weight = 1.0 / self.config.views_per_step
        share = 0.5 * weight if view.crops else weight   # local and global weighed equally
        return _Rendered(view, constants, rendered, leaves, placed, share)

    def _trace_seconds(self) -> float:
        glob = self.global_scene.renderer if self.global_scene is not None else None
        return sum(r.trace_seconds for r in (self.renderer, glob) if isinstance(r, LoopRenderer))

    def _charge_trace(self, phase: str, since: float) -> float:
        """Move the G-buffer tracing done since `since` out of `phase` (just lapped) into "trace"."""
        now = self._trace_seconds()
        self.timer.move(now - since, phase, "trace")
        return now

    def _score(self, items: list["_Rendered"]) -> list[dict]:
        """The rendered views scored (local, then global), back-propagated into the texture, and ε_ψ's
        update on their local latents; each model takes `rows_per_pass` images at a time."""
        images, latents, per_view = self._local(items)
        if any(item.view.crops for item in items):
            check_cancel(self.cancel)   # between the local and the global half
            self._global(items, per_view)
        rendered = [r for item in items for r in item.rendered]
        grads = [torch.nan_to_num(leaf.grad if leaf.grad is not None else torch.zeros_like(leaf),
                                  nan=0.0, posinf=0.0, neginf=0.0).to(r.device)
                 for item in items for leaf, r in zip(item.leaves, item.rendered)]
        torch.autograd.backward(rendered, grads)  # one pass through the texture for all the renders
        self.timer.lap("render_backward")
        views = [item.view for item in items]
        if self.critics.lora is not None:
            # ε_ψ learns the current renderings (its LoRA loss on the detached local latents).
            losses: list[float] = []
            for rows in self._passes(len(views)):
                losses += self.critics.lora.learn_rows(
                    latents[rows], torch.cat([self.models.embed(views[i].prompt) for i in rows]),
                    torch.stack([self._condition(views[i]) for i in rows]), [views[i].rng for i in rows],
                    [views[i].generator for i in rows], self.critics.local.alpha_bar,
                    self.critics.local.prediction_type, [1.0 / self.config.views_per_step] * len(rows))
            for metrics, loss in zip(per_view, losses):
                metrics["lora_loss"] = loss
            self.timer.lap("lora")
        for k, (view, metrics) in enumerate(zip(views, per_view)):
            if view.index == self.my_views[0]:
                self.last_image = images[k:k + 1].detach()
            metrics.update({"t": view.t, "lambda": round(view.lam, 4), "stage_size": view.stage.render_size})
        return per_view

    def _passes(self, count: int) -> list[list[int]]:
        """The rows of `count` images, grouped into the models' passes (all at once when batching)."""
        size = count if self.batch_views else 1
        return [list(range(i, min(i + size, count))) for i in range(0, count, size)]

    def _condition(self, view: ViewSample) -> torch.Tensor:
        return camera_condition(view.camera.origin, view.camera.forward, view.light)

    def _local(self, items: list["_Rendered"]) -> tuple[torch.Tensor, torch.Tensor, list[dict]]:
        """The local views encoded, scored (ε_φ with the reference injected, ε_ψ) and back-propagated to
        their leaves at each view's share of the step. A pass's encoder graph is freed before the next
        pass builds its own (one image at a time unless batching)."""
        images, latents, per_view = [], [], []
        for rows in self._passes(len(items)):
            part = [items[i] for i in rows]
            image = torch.cat([local_view(it.leaves[0][..., 0:3], it.leaves[0][..., 3:4], it.view.background,
                                          self.model_resolution) for it in part])
            z = self.models.encode(image)
            self.timer.lap("vae")
            views, constants = [it.view for it in part], [it.constants for it in part]
            local = self.critics.local(
                z, [v.t for v in views], torch.cat([v.noise for v in views]).to(self.device),
                torch.cat([self.models.embed(v.prompt) for v in views]), self.uncond, lam=[v.lam for v in views],
                condition=torch.stack([self._condition(v) for v in views]),
                reference_latents=_stacked([c.reference_latents for c in constants]),
                weight_map=_stacked([c.weight_map for c in constants]))
            self.timer.lap("unet")
            gradient_loss(z, local.grad * _per_row([it.share for it in part], local.grad)).backward()
            self.timer.lap("vae_backward")
            per_view += [{"local_grad_norm": row["grad_norm"], "nonfinite": row["nonfinite"]} for row in local.row_metrics]
            images.append(image)
            latents.append(z.detach())
        return torch.cat(images), torch.cat(latents), per_view

    def _global(self, items: list["_Rendered"], per_view: list[dict]) -> None:
        """Each crop of the asset in the photo encoded, scored by the inpainting critic (its mask and
        masked-photo latents from the constants) and back-propagated at its view's share / crops."""
        crops = [(k, crop, consts) for k, it in enumerate(items)
                 for crop, consts in zip(it.view.crops, it.constants.crops)]
        glob = self.critics.glob
        assert glob is not None   # (crops are drawn only for global views)
        norms: dict[int, list[float]] = {}
        for rows in self._passes(len(crops)):
            part = [crops[i] for i in rows]
            image = torch.cat([self._crop_of(items[k], crop) for k, crop, _ in part])
            z = self.models.encode(image)
            self.timer.lap("vae")
            views = [items[k].view for k, _, _ in part]
            g = glob(z, [v.t for v in views], torch.cat([v.noise for v in views]).to(self.device),
                     torch.cat([self.models.embed(v.prompt) for v in views]), self.uncond,
                     extra=(torch.cat([c[0] for _, _, c in part]), torch.cat([c[1] for _, _, c in part])))
            self.timer.lap("unet")
            shares = [items[k].share / len(items[k].view.crops) for k, _, _ in part]
            gradient_loss(z, g.grad * _per_row(shares, g.grad)).backward()
            self.timer.lap("vae_backward")
            for (k, _, _), row in zip(part, g.row_metrics):
                norms.setdefault(k, []).append(row["grad_norm"])
                per_view[k]["nonfinite"] += row["nonfinite"]
        for k, values in norms.items():
            per_view[k]["global_grad_norm"] = float(np.mean(values))

    def _crop_of(self, item: "_Rendered", crop):
        """The crop of the photo with this view's asset layer and shadow in it, at the model's size."""
        placed = item.placed
        assert placed is not None and self.photo is not None   # (a view with crops was placed in the photo)
        return global_view(item.leaves[1][..., 0:3], item.leaves[1][..., 3:4], placed.rect, self.photo, placed.matte,
                           crop, self.model_resolution)[0]

    # -- reporting and finish ------------------------------------------------------------------------

    def after_step(self, iteration: int, metrics: dict, progress: ProgressCallback | None) -> None:
        """Progress (with a preview now and then) and the checkpoint, on rank 0."""
        if self.rank != 0:
            return
        config, done = self.config, iteration + 1
        preview = None
        if preview_due(done, config.preview_every, config.iterations, time.monotonic() - self.last_preview) \
                and self.last_image is not None:
            image = self.last_image[0].permute(1, 2, 0).clamp(0, 1).cpu().numpy()
            preview = (image * 255).round().astype(np.uint8)
            self.last_preview = time.monotonic()
        emit(progress, "adapt", done, config.iterations,
             f"{config.mode_type}: {metrics['stage_size']} px, t={metrics['t']}", metrics, preview)
        if self.checkpoint_path is not None and config.checkpoint_every and (
                done % config.checkpoint_every == 0 or done == config.iterations):
            save_checkpoint(self.checkpoint_path, done, config, self.texture, self.optimizer, self.critics.lora,
                            self.history, self.inputs_digest)

    def checkpointed(self, done: int) -> bool:
        """Whether after_step wrote a checkpoint after `done` iterations."""
        every = self.config.checkpoint_every
        return self.checkpoint_path is not None and bool(every) and (done % every == 0 or done == self.config.iterations)

    def keep(self, done: int, saved: int) -> None:
        """A cancelled run's checkpoint at its last finished step (when newer than the last one written), so
        a resume continues the step count from there (rank 0; one rank only: others may be mid-step)."""
        if self.rank != 0 or self.world.choice != 1 or self.checkpoint_path is None or done <= saved:
            return
        save_checkpoint(self.checkpoint_path, done, self.config, self.texture, self.optimizer, self.critics.lora,
                        self.history, self.inputs_digest)

    def finish(self) -> AdaptResult:
        return AdaptResult(texture=self.texture, iterations=self.config.iterations,
                           seconds=time.perf_counter() - self.started, history=self.history,
                           timings=dict(self.timer.totals), resumed_from=self.start, decisions=self.decisions(),
                           peak_memory_mb=peak_memory_mb(self.device))

    def _renderer_decision(self) -> Decision:
        glob = self.global_scene.renderer if self.global_scene is not None else None
        loops = [r for r in (self.renderer, glob) if isinstance(r, LoopRenderer)]
        choice: dict[str, str | int] = {"asked": self.config.renderer,
                                        "local": "loop" if isinstance(self.renderer, LoopRenderer) else "path"}
        if glob is not None:
            choice["global"] = "loop" if isinstance(glob, LoopRenderer) else "path"
        if loops:
            choice.update(traced=sum(r.traced for r in loops), reused=sum(r.reused for r in loops))
        why = {"auto": "the loop renderer where it agrees with path tracing to >= 35 dB on the corpus (local views "
                       "under ambient light, global views under the HDR map), path tracing where it was not shown "
                       "to: benchmarks/results/loop_render.md",
               "loop": "the loop renderer, as asked", "path": "Mitsuba's differentiable path tracing (prb), as asked"}
        reason = why[self.config.renderer]
        if loops:
            reason += "; loop: mesh, cameras and light are fixed, so each view's G-buffer is traced once by Mitsuba " \
                      "and every step shaded in torch"
        if self._path_renderer is not None:
            reason += "; views with their own random light path-traced"
        return Decision(choice, reason)

    def decisions(self) -> dict[str, Decision]:
        config, world = self.config, self.world.choice
        mine = len(self.my_views)
        injected = 0 if self.critics.injector is None else len(self.critics.injector.injected)
        return {
            "mode": Decision(config.mode_type, "the adapt mode asked for"),
            "prompt": Decision(config.effective_prompt, "the prompt given" if config.prompt.strip() else
                               "the object prompt and the instruction combined (appendix, editing)"),
            "critic": Decision(config.critic.critic_type, "VSD with a LoRA ε_ψ (the paper)"
                               if config.critic.critic_type == "vsd" else "SDS (no ε_ψ), as configured"),
            "views": Decision(config.views_type, "local and global views (setup (m))" if config.views_type ==
                              "local+global" else "local views only (no photo)"),
            "reference_injection": Decision(injected, f"the reference's keys and values injected into {injected} "
                                            "attention layers" if injected else "no reference injection"),
            "renderer": self._renderer_decision(),
            "world_size": self.world,
            "constant_work": Decision(
                {"cached": self.constants.cache, "bank": len(self.bank or ()), "computed": self.constants.misses,
                 "reused": self.constants.hits},
                "reference latents, normal weights, crop masks and masked-photo latents computed once per view of "
                "the fixed bank" if self.constants.cache and self.bank else "recomputed every step"),
            "views_per_step": Decision(config.views_per_step,
                                       f"{mine} view(s) rendered in turn on this rank, gradients averaged"
                                       + (f" over {world} ranks" if world > 1 else "")),
            "batched_views": Decision(
                {"asked": self.batch_views, "steps": self.batched_steps},
                "the steps whose views went through the VAE, each UNet and ε_ψ's update in one pass per model "
                "(their renders, the loop renderer's, wait for one backward); the others' views one at a time"
                if self.batch_views else "one image at a time through each model, as asked (least memory)"),
            "models": Decision({k: str(v) for k, v in self.models.paths.items()}, "where the weights were found"),
            "device": Decision(str(self.device), f"{str(self.models.dtype).replace('torch.', '')} UNet"),
        }


@dataclass
class _Rendered:
    """One view of a step, rendered: what its scoring needs."""

    view: ViewSample
    constants: ViewConstants
    rendered: list[torch.Tensor]     # the renders (local; the asset in the photo), in the texture's graph
    leaves: list[torch.Tensor]       # the same, detached on the models' device: where the critics' gradients stop
    placed: GlobalRender | None
    share: float                     # the weight of each half (local, global) in the step


def _stacked(rows: list[torch.Tensor | None]) -> torch.Tensor | None:
    """The views' tensors of one kind as one batch (None where the views have none)."""
    return None if rows[0] is None else torch.cat(rows)


def _per_row(values: list[float], like: torch.Tensor) -> torch.Tensor:
    """(B, 1, 1, 1): one number per row of `like`."""
    return torch.tensor(values, dtype=like.dtype, device=like.device).view(-1, *([1] * (like.ndim - 1)))
