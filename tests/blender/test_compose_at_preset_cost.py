"""The Compose button renders at the quality preset's cost, as Run All's compose does: the preset's sample cap
with the denoiser (at Draft, 16 samples; the composite scene's own 128 are for the artist's F12), says so, and
leaves the composite scene's own settings as they were."""
import pytest

from conftest import printed_json

pytestmark = pytest.mark.blender


def test_compose_renders_at_the_presets_samples_and_keeps_the_scenes_own(run_py, tmp_path):
    proc = run_py(f"""
        import json
        from pathlib import Path
        import numpy as np
        import bpy, addon_utils
        bpy.ops.wm.read_factory_settings(use_empty=True)
        addon_utils.enable("scenefit", default_set=True)
        from scenefit.blender_io.compose import COMPOSITE_SAMPLES
        from scenefit.core.data.imageio import write_image
        from scenefit.core.pipeline.preset_tables import TABLES
        tmp = Path({str(tmp_path)!r})
        write_image(tmp / "photo.png", np.random.default_rng(1).uniform(0.2, 0.8, (24, 32, 3)).astype(np.float32))
        bpy.ops.wm.save_as_mainfile(filepath=str(tmp / "scene.blend"))
        bpy.ops.mesh.primitive_uv_sphere_add(segments=8, ring_count=4)
        s = bpy.context.scene.scenefit
        s.photo_path, s.placement, s.preset = str(tmp / "photo.png"), (0.5, 0.8), "draft"
        seen = []
        bpy.app.handlers.render_pre.append(lambda scene, *_: seen.append(
            [scene.name, scene.cycles.samples, scene.cycles.use_denoising, scene.render.resolution_percentage,
             scene.cycles.use_adaptive_sampling, round(scene.cycles.adaptive_threshold, 3)]))
        bpy.ops.scenefit.compose(render=False)   # the composite scene, set up as an artist's F12 finds it
        own = bpy.data.scenes["SceneFit Composite"]
        before = [own.cycles.samples, own.cycles.use_denoising, own.cycles.denoiser, own.render.resolution_percentage,
                  own.cycles.use_adaptive_sampling, own.cycles.adaptive_threshold, own.cycles.denoising_prefilter]
        TABLES["compose"]["draft"]["max_side"] = 16   # (draft's 2048 on a photo of 32 px: half its size, quickly)
        result = sorted(bpy.ops.scenefit.compose())
        print("JSON" + json.dumps({{"result": result, "seen": seen, "draft": TABLES["compose"]["draft"]["max_spp"],
                                  "noise": TABLES["compose"]["draft"]["noise_target"],
                                  "own": COMPOSITE_SAMPLES, "before": before,
                                  "after": [own.cycles.samples, own.cycles.use_denoising, own.cycles.denoiser,
                                            own.render.resolution_percentage, own.cycles.use_adaptive_sampling,
                                            own.cycles.adaptive_threshold, own.cycles.denoising_prefilter]}}))
    """, timeout=600)
    out = printed_json(proc)
    assert out["result"] == ["FINISHED"], proc.stderr[-2000:]
    assert out["draft"] < out["own"]   # (else the test could not tell the two apart)
    # the preset's samples, denoised, at the preset's long side (16 of the photo's 32 px here)
    assert out["seen"] == [["SceneFit Composite", out["draft"], True, 50, True, out["noise"]]]
    assert out["after"] == out["before"] and out["before"][0] == out["own"]      # the scene's own, back
    assert "at the Draft preset's noise target, at most 16 samples, denoised, 50% of the photo's size" in \
        proc.stdout + proc.stderr
