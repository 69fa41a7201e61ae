"""Adapt-stage speed: seconds per iteration split into render, VAE, UNet and LoRA, and peak memory.

CPU: tiny random-weight models (devtools/tiny_models.py), 32-64 px renders, so the numbers measure
the stage's own overhead, not Stable Diffusion. Where CUDA is available, also an SD2-sized
random-weight UNet in fp16 at setup (m)'s 512 px, 128 spp and 4 views per step.

`bench_adapt(quick)` returns {"rows": [...], "markdown": str, "batched": [...]}; `python
benchmarks/bench_adapt.py` prints the table. benchmarks/run.py can import and call it. `--batched`
writes results/adapt_batched.md (a step's views through each model in one pass against one image at
a time), `--render-phases` results/render_phases.md, `--renderers` results/adapt_renderers.md.
"""
from __future__ import annotations

import sys
import tempfile
import subprocess
import platform
import os
import time
from pathlib import Path

import numpy as np
import torch

from scenefit.core.stages.adapt import AdaptConfig, AdaptInputs, StageSpec, adapt_texture
from scenefit.core.guidance import ModelConfig
from scenefit.core.pipeline.presets import stage_config
from scenefit.core.data.primitives import uv_sphere
from scenefit.core.scene.placement import Placement
from scenefit.core.data.uv_raster import rasterize_uv
from scenefit.core.texture import NeuralTexture
from scenefit.devtools.tiny_models import SD2_UNET, build_tiny_pair, build_tiny_sd

sys.path.insert(0, str(Path(__file__).resolve().parent))
from results_files import machine_load  # noqa: E402

PHASES = (("constant work", "constants"), ("G-buffer trace", "trace"), ("render", "render"), ("VAE encode", "vae"), ("UNet passes", "unet"), ("VAE backward", "vae_backward"),
          ("render backward", "render_backward"), ("LoRA loss + backward", "lora"), ("Adam steps", "step"))


def _run(base: Path, inpaint: Path, model_resolution: int, stages, iterations: int, views_type: str,
         dtype_type: str = "auto", views_per_step: int = 1, warmup: int = 2, renderer: str = "path") -> dict:
    mesh = uv_sphere(segments=32, rings=16)
    raster = rasterize_uv(mesh, 128)
    texture = NeuralTexture(stage_config("texture", "draft", resolution=128), seed=0)
    photo = np.random.default_rng(0).uniform(0.2, 0.8, (96, 128, 3)).astype(np.float32)
    config = AdaptConfig(prompt="a mossy sphere in a swamp", iterations=iterations, stages=stages,
                         model_resolution=model_resolution, views_type=views_type, checkpoint_every=0, preview_every=0,
                         views_per_step=views_per_step, renderer=renderer,
                         models=ModelConfig(base_model=str(base), inpaint_model=str(inpaint), dtype_type=dtype_type))
    inputs = AdaptInputs(mesh=mesh, raster=raster, texture=texture, photo=photo, placement=Placement((0.5, 0.6), 0.5))
    if warmup:
        adapt_texture(inputs, AdaptConfig(**{**config.__dict__, "iterations": warmup}))  # warm-up: kernels compiled
    if torch.cuda.is_available():
        torch.cuda.reset_peak_memory_stats()
    t = time.perf_counter()
    result = adapt_texture(inputs, config)
    wall = (time.perf_counter() - t) / iterations
    per = result.seconds_per_iteration()
    return {"phases": {k: per.get(k, 0.0) for _, k in PHASES}, "iteration_s": sum(per.values()), "wall_s": wall,
            "peak_memory_mb": result.peak_memory_mb, "device": result.decisions["device"].choice,
            "views_per_step": result.decisions["views_per_step"].choice,
            "batched_steps": result.decisions["batched_views"].choice["steps"]}


def preset_row(preset: str, iterations: int, spp_cut: int = 8) -> dict:
    """Seconds per iteration at `preset`'s render sizes and views per step with tiny models, the samples
    per pixel cut by `spp_cut` (the same for every preset: final's 512² at 128 spp and 4 views took
    minutes per iteration on 2 shared cores). Rendering is linear in samples, so the preset's own cost
    is projected as render phases x spp_cut + the rest. benchmarks/trade.py runs this in a child process."""
    from dataclasses import replace

    config = stage_config("adapt", preset, prompt="x")
    stages = tuple(replace(s, spp=max(1, s.spp // spp_cut)) for s in config.stages)
    with tempfile.TemporaryDirectory() as tmp:
        base, inpaint = build_tiny_pair(tmp)
        row = _run(base, inpaint, 64, stages, iterations, config.views_type,
                   views_per_step=config.views_per_step, warmup=1)
    per = row["phases"]
    render = per["render"] + per["render_backward"]
    full = render * config.stages[0].spp / stages[0].spp + (row["iteration_s"] - render)
    return {"render_size": stages[0].render_size, "spp": config.stages[0].spp, "measured_spp": stages[0].spp,
            "views_per_step": config.views_per_step, "preset_iterations": config.iterations,
            "iteration_s": row["iteration_s"], "render_s": render, "projected_iteration_s": full,
            "projected_s": full * config.iterations, "phases": per}


def bench_adapt(quick: bool = False) -> dict:
    rows = []
    iterations = 3 if quick else 10
    with tempfile.TemporaryDirectory() as tmp:
        base, inpaint = build_tiny_pair(tmp)
        for size, views, per_step in ((32, "local", 1), (64, "local+global", 1), (64, "local+global", 4)):
            for renderer in ("loop", "path"):
                stages = (StageSpec(1.0, size, 8, (500, 990)),)
                row = _run(base, inpaint, size, stages, iterations, views, views_per_step=per_step, renderer=renderer)
                row["setup"] = f"tiny models, CPU, {size} px, {views}, {per_step} view(s)/step, 2 crops, {renderer} renderer"
                rows.append(row)
        if torch.cuda.is_available():
            sd2 = build_tiny_sd(Path(tmp) / "sd2-sized", 4, **SD2_UNET)
            sd2_inpaint = build_tiny_sd(Path(tmp) / "sd2-sized-inpaint", 9, seed=1, **SD2_UNET)
            stages = (StageSpec(1.0, 512, 128, (500, 990)),)   # setup (m)'s render size and spp
            row = _run(sd2, sd2_inpaint, 512, stages, 3 if quick else 6, "local+global", "fp16", views_per_step=4)
            row["setup"] = (f"SD2-sized UNet (random weights), {torch.cuda.get_device_name()}, fp16, 512 px, 128 spp, "
                            "local+global, 4 views/step, 2 crops")
            rows.append(row)
    head = "| setup | " + " | ".join(title for title, _ in PHASES) + " | s / iteration | peak memory MB |"
    rule = "|" + "---|" * (len(PHASES) + 3)
    body = [f"| {r['setup']} | " + " | ".join(f"{r['phases'][k]:.3f}" for _, k in PHASES)
            + f" | {r['iteration_s']:.3f} | {r['peak_memory_mb']:.0f} |" for r in rows]
    note = ("Peak memory: process resident set on CPU (includes Mitsuba and torch), "
            "torch.cuda.max_memory_allocated on GPU.")
    batched = batched_views(iterations=2 if quick else 4)   # results/adapt_batched.md: 8, --batched
    markdown = "\n".join(["Adapt stage, seconds per iteration by phase (after a warm-up run):", "", head, rule,
                          *body, "", note, "", batched["markdown"]])
    return {"rows": rows, "markdown": markdown, "batched": batched["rows"]}


def batched_views(iterations: int = 8, views_per_step: int = 4, size: int = 64, dtype_type: str = "auto") -> dict:
    """A step's views through each model in one pass (`AdaptSystem.train_views`) against one image at a
    time (AdaptConfig.batch_views False), tiny models, the loop renderer, local + global views with 2 crops: seconds
    per step by phase once the views' G-buffers and constant work are made (step 0, not timed). Two
    systems side by side in one process take their steps in turn (which goes first alternates), so both
    see the same load; each phase is the median over the steps."""
    from dataclasses import replace

    from scenefit.core.stages.adapt import AdaptSystem

    timed: dict[bool, list[dict]] = {True: [], False: []}
    with tempfile.TemporaryDirectory() as tmp:
        base, inpaint = build_tiny_pair(tmp)
        mesh = uv_sphere(segments=32, rings=16)
        photo = np.random.default_rng(0).uniform(0.2, 0.8, (96, 128, 3)).astype(np.float32)
        config = AdaptConfig(prompt="a mossy sphere in a swamp", iterations=iterations + 1,
                             stages=(StageSpec(1.0, size, 8, (500, 990)),), model_resolution=size, views=views_per_step,
                             view_variants=1, views_per_step=views_per_step, global_crops=2, checkpoint_every=0,
                             preview_every=0, renderer="loop",
                             models=ModelConfig(base_model=str(base), inpaint_model=str(inpaint), dtype_type=dtype_type))
        inputs = AdaptInputs(mesh=mesh, raster=rasterize_uv(mesh, 128), photo=photo, placement=Placement((0.5, 0.6), 0.5),
                             texture=NeuralTexture(stage_config("texture", "draft", resolution=128), seed=0))
        systems = {batch: AdaptSystem.build(inputs, replace(config, batch_views=batch)) for batch in (True, False)}
        for system in systems.values():
            system.step(0)                                      # G-buffers and constant work, not timed
        for i in range(iterations):
            for batch in ((True, False) if i % 2 == 0 else (False, True)):
                system = systems[batch]
                before = dict(system.timer.totals)
                system.step(i + 1)
                timed[batch].append({k: v - before.get(k, 0.0) for k, v in system.timer.totals.items()})
        assert systems[True].batched_steps == iterations + 1 and systems[False].batched_steps == 0
    load = machine_load()
    rows = []
    for batch in (True, False):
        phases = {k: float(np.median([step.get(k, 0.0) for step in timed[batch]])) for _, k in PHASES}
        rows.append({"batched": batch, "phases": phases, "step_s": float(np.median([sum(st.values()) for st in timed[batch]])),
                     "steps": len(timed[batch]), "views_per_step": views_per_step, "size": size,
                     "dtype": str(systems[batch].models.dtype).replace("torch.", ""), "load": load})
    together, alone = rows
    models = ("vae", "unet", "vae_backward", "lora")
    lines = [f"A step's {views_per_step} views (local + global, 2 crops each, {size} px, loop renderer, tiny models in "
             f"{together['dtype']}) through each model in one pass, against one image at a time; median seconds per "
             f"step by phase over {together['steps']} steps each, two systems taking their steps in turn in one "
             f"process ({load}).", "",
             "| views through the models | " + " | ".join(title for title, _ in PHASES) + " | s / step |",
             "|" + "---|" * (len(PHASES) + 2)]
    for r in rows:
        lines.append(f"| {'one pass per model' if r['batched'] else 'one image at a time'} | "
                     + " | ".join(f"{r['phases'][k]:.3f}" for _, k in PHASES) + f" | {r['step_s']:.3f} |")
    lines += ["", f"The models' phases (VAE, UNet, VAE backward, LoRA): {sum(alone['phases'][k] for k in models):.3f} s "
              f"one at a time, {sum(together['phases'][k] for k in models):.3f} s in one pass per model; the step "
              f"{alone['step_s'] / together['step_s']:.2f}x faster batched."]
    return {"rows": rows, "markdown": "\n".join(lines) + "\n"}


def final_step_renderers(iterations: int = 2, spp_cut: int = 8) -> dict:
    """The final preset's step (512 px renders, 4 views, local + global with 2 crops) with tiny models,
    rendered by the loop renderer and by path tracing, in one process so the two are compared under the
    same load: seconds per step by phase once each view's G-buffer is traced (a one-view bank, so every
    step after the first meets it again). Path tracing runs at spp / `spp_cut` and its render phases are
    projected to the preset's spp (rendering is linear in samples); the loop renderer's do not depend on spp."""
    from dataclasses import replace

    from scenefit.core.stages.adapt import AdaptSystem

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        base, inpaint = build_tiny_pair(tmp)
        mesh = uv_sphere(segments=64, rings=32)
        photo = np.random.default_rng(0).uniform(0.2, 0.8, (480, 640, 3)).astype(np.float32)
        for renderer in ("loop", "path"):
            config = stage_config("adapt", "final", prompt="a mossy sphere in a swamp", checkpoint_every=0,
                                  preview_every=0, views=1, view_variants=1, model_resolution=64, renderer=renderer,
                                  models=ModelConfig(base_model=str(base), inpaint_model=str(inpaint)))
            cut = spp_cut if renderer == "path" else 1
            config = replace(config, stages=tuple(replace(s, spp=max(1, s.spp // cut)) for s in config.stages))
            inputs = AdaptInputs(mesh=mesh, raster=rasterize_uv(mesh, 512), photo=photo,
                                 placement=Placement((0.5, 0.6), 0.5),
                                 texture=NeuralTexture(stage_config("texture", "final", resolution=512), seed=0))
            system = AdaptSystem.build(inputs, config)
            t = time.perf_counter()
            system.step(0)                                   # cold: the view's constant work and G-buffers
            cold = time.perf_counter() - t
            before = dict(system.timer.totals)
            for i in range(iterations):
                system.step(i + 1)
            per = {k: (v - before.get(k, 0.0)) / iterations for k, v in system.timer.totals.items()}
            render = (per.get("render", 0.0) + per.get("render_backward", 0.0)) * cut
            rows.append({"renderer": renderer, "render_size": config.stages[0].render_size,
                         "spp": config.stages[0].spp * cut, "measured_spp": config.stages[0].spp,
                         "views_per_step": config.views_per_step, "phases": per, "cold_step_s": cold,
                         "render_and_backward_s": render,
                         "step_s": sum(per.values()) + render - per.get("render", 0.0) - per.get("render_backward", 0.0),
                         "gbuffer_mb": (system.renderer.cached_bytes() + system.global_scene.renderer.cached_bytes())
                         / 2 ** 20 if renderer == "loop" else None, "load": machine_load()})
    lines = ["# The final preset's step: loop renderer vs path tracing (tiny models, this CPU)", "",
             "`python benchmarks/bench_adapt.py --renderers`: final (512 px, 128 spp, 4 views/step, local + global, "
             "2 crops), tiny random-weight models at 64 px, one process (same load for both). Path tracing measured at "
             f"128 / {spp_cut} spp, its render phases projected x{spp_cut}. Seconds per step once the view's G-buffers "
             "are traced ('cold step': the first, which traces them).", "",
             "| renderer | render s | render backward s | render + backward s | step s | cold step s | G-buffers MB | load |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        cut = r["spp"] // r["measured_spp"] if r["renderer"] == "path" else 1
        lines.append(f"| {r['renderer']} | {r['phases'].get('render', 0) * cut:.2f} | "
                     f"{r['phases'].get('render_backward', 0) * cut:.2f} | {r['render_and_backward_s']:.2f} | "
                     f"{r['step_s']:.2f} | {r['cold_step_s']:.1f} | "
                     f"{'' if r['gbuffer_mb'] is None else round(r['gbuffer_mb'])} | "
                     f"{r['load'].split('load average:')[-1].strip()} |")
    loop, path = rows
    lines += ["", f"Render + backward per step: loop {loop['render_and_backward_s']:.2f} s, path "
              f"{path['render_and_backward_s']:.1f} s: {path['render_and_backward_s'] / loop['render_and_backward_s']:.0f}x "
              "less with the loop renderer, measured under the same load."]
    return {"rows": rows, "markdown": "\n".join(lines) + "\n"}


def render_phases(size: int = 512, views: int = 4, spp: int = 128, spp_cut: int = 8, repeats: int = 2,
                  measured: int = 1) -> dict:
    """The final preset's render phases alone (no models): per step, `views` local views and as many global
    ones (2 x `views` renders of `size` px, as a final step renders), forward and backward to a 512²
    texture, by the loop renderer (G-buffers traced once, before timing) and by path tracing (Mitsuba
    prb at spp / `spp_cut`, projected to `spp`: rendering is linear in samples), in one process.
    `measured` of the renders are timed and the step projected from them (each render costs the same)."""
    from scenefit.core.render.gbuffer import GBufferOptions
    from scenefit.core.render.loop_renderer import LoopRenderer
    from scenefit.core.render.orbit_camera import Camera
    from scenefit.core.render.renderer import AssetRenderer, SceneOptions

    mesh = uv_sphere(segments=64, rings=32)
    # The local views are lit by the constant ambient light, the global ones by the estimated map: one of each
    # is timed (a loop renderer's G-buffer depends on its light) and the step projected from them.
    ambient = np.ones((16, 32, 3), np.float32)
    light_map = np.full((16, 32, 3), 0.4, np.float32)
    light_map[3:5, 9:11] = 60.0   # a sun
    cameras = [(Camera(360.0 * i / (2 * views), 15.0, 1.1, width=size, height=size), env)
               for i in range(measured) for env in (ambient, light_map)]
    per_step = 2 * views / len(cameras)
    options = SceneOptions(max_depth=3, hide_emitters=True)
    maps = torch.rand(512, 512, 5, generator=torch.Generator().manual_seed(0)).requires_grad_(True)
    rows = []
    # The loop renderer as it is, as it was before each sample shaded its own texture values (4 samples
    # per pixel, 16 diffuse rays each), and path tracing.
    gbuffers = {"loop": GBufferOptions(),
                "loop, 16 samples for every view": GBufferOptions(map_samples=16, map_diffuse_rays=4),
                "loop, 4 samples for every view": GBufferOptions(samples=4, diffuse_rays=16)}
    for name in (*gbuffers, "path"):
        renderer = (LoopRenderer(mesh, (512, 512), ambient, options, gbuffer=gbuffers[name]) if name in gbuffers
                    else AssetRenderer(mesh, (512, 512), ambient, options))
        t = time.perf_counter()
        if name in gbuffers:
            for camera, env in cameras:
                renderer.gbuffer(camera, torch.from_numpy(env))
        trace = time.perf_counter() - t
        cut = (spp_cut if name == "path" else 1) * per_step
        forward = backward = 0.0
        for _ in range(repeats):
            for camera, env in cameras:
                t = time.perf_counter()
                out = renderer.render(camera, maps[..., 0:3], maps[..., 3:4], maps[..., 4:5], torch.from_numpy(env),
                                      spp=spp // spp_cut, seed=1)
                t1 = time.perf_counter()
                out.rgb.sum().backward()
                forward, backward = forward + t1 - t, backward + time.perf_counter() - t1
        rows.append({"renderer": name, "renders_per_step": 2 * views, "measured_renders": len(cameras), "size": size,
                     "spp": spp, "measured_spp": spp // spp_cut if name == "path" else None, "render_s": forward / repeats * cut,
                     "render_backward_s": backward / repeats * cut, "trace_s": trace, "load": machine_load()})
    loop, all16, all4, path = rows
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                            cwd=Path(__file__).resolve().parent).stdout.strip()
    lines = ["# The final preset's render phases: loop renderer vs path tracing (this CPU)", "",
             f"Commit {commit}, {platform.machine()} with {os.cpu_count()} cores, "
             f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}.", "",
             f"`python benchmarks/bench_adapt.py --render-phases`: per step {2 * views} renders of {size} px (4 local "
             "views and 4 global ones, as final renders), forward and backward to a 512² texture, one process (same "
             f"load for both). Path tracing (prb, max_depth 3) measured at {spp // spp_cut} spp and projected to {spp}; "
             "the loop renderer's G-buffers traced once before timing ('trace s', once per view for a whole run). "
             f"{len(cameras)} of the {2 * views} renders timed ({repeats} times), one local view under the ambient "
             "light and one global view under a light map, the step projected from them. The loop renderer traces "
             "16 samples per pixel for views under a constant light and 4 under a map (GBufferOptions).", "",
             "| renderer | render s / step | render backward s / step | render + backward s / step | trace s (once) | load |",
             "|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['renderer']} | {r['render_s']:.2f} | {r['render_backward_s']:.2f} | "
                     f"{r['render_s'] + r['render_backward_s']:.2f} | {r['trace_s']:.1f} | "
                     f"{r['load'].split('load average:')[-1].strip()} |")
    ratio = (path["render_s"] + path["render_backward_s"]) / (loop["render_s"] + loop["render_backward_s"])
    cost = (all16["render_s"] + all16["render_backward_s"]) / (all4["render_s"] + all4["render_backward_s"])
    lines += ["", f"The loop renderer's render + backward per step is {ratio:.0f}x less than path tracing's under the "
              f"same load; 16 samples per pixel for every view would cost {cost:.1f}x 4 for every view (16 are what "
              "agreeing with path tracing under ambient light takes, benchmarks/results/loop_render.md)."]
    return {"rows": rows, "markdown": "\n".join(lines) + "\n"}


def sd2_row(models: Path, preset: str, dtype_type: str, cache: bool) -> dict:
    """A preset's scene-mode step with SD2-sized random models (devtools SD2_SIZED, built in
    `models`/sd2-base and sd2-inpaint): step 0 run twice, the first with the view's constant work
    computed (cold), the second reusing it when `cache` (warm); seconds by phase per step and the
    process's peak resident memory. Meant for a process of its own (peak memory is the process's)."""
    from scenefit.core.stages.adapt import AdaptSystem
    from scenefit.core.stages.adapt.metrics import peak_memory_mb

    config = stage_config("adapt", preset, prompt="a mossy sphere in a swamp", checkpoint_every=0, preview_every=0,
                          models=ModelConfig(base_model=str(models / "sd2-base"),
                                             inpaint_model=str(models / "sd2-inpaint"), dtype_type=dtype_type))
    mesh = uv_sphere(segments=32, rings=16)
    photo = np.random.default_rng(0).uniform(0.2, 0.8, (480, 640, 3)).astype(np.float32)
    inputs = AdaptInputs(mesh=mesh, raster=rasterize_uv(mesh, 128), photo=photo, placement=Placement((0.5, 0.6), 0.5),
                         texture=NeuralTexture(stage_config("texture", preset, resolution=128), seed=0))
    started = time.perf_counter()
    system = AdaptSystem.build(inputs, config, cache_constants=cache)
    build_s = time.perf_counter() - started
    steps = []
    for _ in range(2):
        before = dict(system.timer.totals)
        system.step(0)
        steps.append({k: v - before.get(k, 0.0) for k, v in system.timer.totals.items()})
    stage = config.stages[0]
    return {"setup": f"{preset} ({stage.render_size} px, {stage.spp} spp, {config.views_per_step} view(s), "
                     f"{config.global_crops} crops, {config.model_resolution}-px model input), "
                     f"{str(system.models.dtype).removeprefix('torch.')}, "
                     f"constants {'cached' if cache else 'recomputed'}",
            "preset": preset, "iterations": config.iterations, "dtype": str(system.models.dtype), "cache": cache, "build_s": build_s,
            "cold": steps[0], "warm": steps[1], "cold_s": sum(steps[0].values()), "warm_s": sum(steps[1].values()),
            "peak_memory_mb": peak_memory_mb(system.device), "load": machine_load()}


def sd2_markdown(rows: list[dict], light: list[dict] = ()) -> str:
    """The SD2-size rows (sd2_row's, one process each) as a table: per step, cold and warm."""
    lines = ["# Adapt at SD2 size on this CPU (random weights), scene mode\n",
             "`python benchmarks/bench_adapt.py --sd2 MODELS PRESET DTYPE cache|nocache OUT.json`, each row its own process; "
             "'cold': the step that first meets its view (constant work computed), 'warm': the same view again "
             "(constant work reused when cached). Seconds; peak resident memory of the process.\n",
             "| setup | peak GB | cold step s | warm step s | " + " | ".join(f"warm {name}" for name, _ in PHASES) + " | load |",
             "|---|---|---|---|" + "---|" * len(PHASES) + "---|"]
    for r in rows:
        phases = " | ".join(f"{r['warm'].get(key, 0.0):.1f}" for _, key in PHASES)
        lines.append(f"| {r['setup']} | {r['peak_memory_mb'] / 1024:.2f} | {r['cold_s']:.1f} | {r['warm_s']:.1f} | "
                     f"{phases} | {r['load'].split('load average:')[-1].strip()} |")
    if light:
        lines += ["\nThe light stage's diffusion critic with the same models (`scenefit light --critic diffusion`):\n",
                  "| setup | s per iteration | peak GB | load |", "|---|---|---|---|"]
        lines += [f"| {r['setup']} | {r['per_iteration_s']:.1f} | {r['peak_memory_mb'] / 1024:.2f} | "
                  f"{r['load'].split('load average:')[-1].strip()} |" for r in light]
    return "\n".join(lines) + "\n"


def sd2_light_row(models: Path, folder: Path, iterations: int = 2) -> dict:
    """`scenefit light --critic diffusion --preset draft` with the SD2-size models on a corpus view
    (benchmarks/corpus.photo_from), in a process of its own: seconds per critic iteration from its
    report, and the peak resident memory of this process's children (run it before any other child)."""
    import json
    import resource
    import subprocess

    from corpus import photo_from

    photo = photo_from("noon_grass_1k", folder / "noon.png")
    out = folder / "light"
    subprocess.run([sys.executable, "-m", "scenefit.cli", "light", "--photo", str(photo), "--at", "0.5,0.75",
                    "--out", str(out), "--preset", "draft", "--critic", "diffusion", "--iterations", str(iterations),
                    "--outpaint", "prior", "--base-model", str(models / "sd2-base"), "--inpaint-model",
                    str(models / "sd2-inpaint"), "--offline", "--quiet"], check=True, capture_output=True)
    report = json.loads((out / "report.json").read_text())
    seconds = report["decisions"]["optimisation"]["seconds"]
    return {"setup": f"light, diffusion critic, draft ({iterations} iterations), "
                     f"{report['decisions']['critic'].get('dtype', '?')}",
            "per_iteration_s": seconds / iterations,
            "peak_memory_mb": resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0, "load": machine_load()}


def sd2_bench(presets: tuple[str, ...] = ("draft", "balanced")) -> Path:
    """`make bench`'s SD2-size part: builds the random models once (benchmarks/gpu_check.build_models),
    then per preset a bf16 cached row, and for draft the fp32 uncached row it is compared with, each in
    a process of its own (peak memory is the process's); writes results/adapt_sd2.md and .json."""
    import json
    import subprocess

    from gpu_check import build_models

    with tempfile.TemporaryDirectory(prefix="scenefit-sd2-") as tmp:
        folder = Path(tmp)
        build_models(folder / "models", dry_run=False)
        light = sd2_light_row(folder / "models", folder)   # first: its peak is then the only child's
        runs = [(preset, "auto", "cache") for preset in presets] + [("draft", "fp32", "nocache")]
        rows = []
        for preset, dtype, cache in runs:
            out = folder / f"{preset}_{dtype}_{cache}.json"
            subprocess.run([sys.executable, __file__, "--sd2", str(folder / "models"), preset, dtype, cache, str(out)],
                           check=True, capture_output=True)
            rows.append(json.loads(out.read_text()))
    from results_files import write_results

    return write_results(Path(__file__).resolve().parent / "results", "adapt_sd2", sd2_markdown(rows, [light]),
                         {"rows": rows, "light": [light]})


if __name__ == "__main__":
    if "--render-phases" in sys.argv:   # python benchmarks/bench_adapt.py --render-phases (-> results/render_phases)
        from results_files import write_results

        out = render_phases()
        print(write_results(Path(__file__).resolve().parent / "results", "render_phases", out["markdown"],
                            {"rows": out["rows"]}))
        print(out["markdown"])
    elif "--batched" in sys.argv:   # python benchmarks/bench_adapt.py --batched (-> results/adapt_batched)
        from results_files import write_results

        out = batched_views()
        print(write_results(Path(__file__).resolve().parent / "results", "adapt_batched",
                            "# A step's views through each model in one pass (tiny models, this CPU)\n\n" + out["markdown"],
                            {"rows": out["rows"]}))
        print(out["markdown"])
    elif "--renderers" in sys.argv:   # python benchmarks/bench_adapt.py --renderers (-> results/adapt_renderers)
        from results_files import write_results

        out = final_step_renderers()
        print(write_results(Path(__file__).resolve().parent / "results", "adapt_renderers", out["markdown"],
                            {"rows": out["rows"]}))
        print(out["markdown"])
    elif "--sd2-bench" in sys.argv:   # python benchmarks/bench_adapt.py --sd2-bench (-> results/adapt_sd2)
        print(sd2_bench())
    elif "--sd2-table" in sys.argv:   # python benchmarks/bench_adapt.py --sd2-table ROW.json ... (-> results/adapt_sd2)
        import json

        from results_files import write_results

        files = [json.loads(Path(f).read_text()) for f in sys.argv[sys.argv.index("--sd2-table") + 1:]]
        rows, light = [r for r in files if "warm_s" in r], [r for r in files if "per_iteration_s" in r]
        print(write_results(Path(__file__).resolve().parent / "results", "adapt_sd2", sd2_markdown(rows, light),
                            {"rows": rows, "light": light}))
    elif "--sd2" in sys.argv:   # python benchmarks/bench_adapt.py --sd2 MODELS PRESET DTYPE cache|nocache OUT.json
        import json

        folder, preset, dtype, cache, out = sys.argv[sys.argv.index("--sd2") + 1:][:5]
        row = sd2_row(Path(folder), preset, dtype, cache == "cache")
        Path(out).write_text(json.dumps(row, indent=1, default=str) + "\n")
        print(json.dumps(row, indent=1, default=str))
    else:
        out = bench_adapt(quick="--quick" in sys.argv)
        print(out["markdown"])
