"""The composite cross-checked in Blender's Cycles: same camera, World from the same light EXR, same
placed asset, floor shadow as the ratio of floor renders with and without the asset, photo behind."""
from __future__ import annotations

import json

import numpy as np

from scenefit.core.stages.compose import ComposeConfig, ComposeInputs, build_compose
from scenefit.core.data.imageio import linear_to_srgb, read_image, srgb_to_linear, write_image
from scenefit.core.render.environment import sun_environment
from scenefit.core.texture.views import image_psnr
from scenefit.core.data.primitives import uv_sphere
from scenefit.core.scene.camera import PhotoCamera

CAMERA = PhotoCamera(yaw_deg=90.0, pitch_deg=-20.0, fov_deg=60.0, width=128, height=96)
# Measured on the development machine (AMD EPYC, 2 cores; Mitsuba 64 spp + OIDN, Cycles 32 samples +
# its denoiser): IoU 1.000, shadow correlation 0.989, PSNR 41.1 dB. Thresholds sit a little below.
MIN_IOU, MIN_SHADOW_CORRELATION, MIN_PSNR_DB = 0.97, 0.95, 35.0


def test_mitsuba_composite_matches_cycles(tmp_path, run_py):
    # A base colour red in the image's top half and blue in its bottom half (the sphere's v runs
    # pole to pole) also checks that both renderers read the UVs the same way up.
    base = np.zeros((16, 16, 3), np.float32)
    base[:8] = (0.7, 0.15, 0.1)
    base[8:] = (0.1, 0.2, 0.7)
    maps = np.concatenate([base, np.full((16, 16, 1), 0.5, np.float32), np.zeros((16, 16, 1), np.float32)], -1)
    photo = np.full((CAMERA.height, CAMERA.width, 3), 0.6, np.float32)
    env = sun_environment([1.0, 0.3, 0.8], sun_radiance=500.0, sky_radiance=0.3)
    write_image(tmp_path / "light.exr", env, dtype="float")
    write_image(tmp_path / "base_color.png", linear_to_srgb(base))

    job = build_compose(ComposeInputs(uv_sphere(0.5, 32, 16), maps, photo, (64.0, 66.0), env, CAMERA),
                        ComposeConfig(size=0.3, spp=64))
    while not job.done:
        job.step()
    mitsuba = job.finish()
    placed = job.mesh
    np.savez(tmp_path / "placed.npz", positions=placed.positions, faces=placed.faces, uvs=placed.uvs,
             normals=placed.normals)

    run_py(f"""
        import json, numpy as np, bpy, addon_utils
        addon_utils.enable('cycles')
        bpy.ops.wm.read_factory_settings(use_empty=True)
        from scenefit.blender_io.cycles_crosscheck import composite_scene, render_passes
        from scenefit.core.data.mesh import Mesh
        from scenefit.core.scene.camera import PhotoCamera
        d = np.load({str(tmp_path / 'placed.npz')!r})
        mesh = Mesh.from_arrays(d['positions'], d['faces'], d['uvs'], d['normals'])
        camera = PhotoCamera(**{json.dumps(CAMERA.__dict__)})
        objects = composite_scene(mesh, {{"base_color": {str(tmp_path / 'base_color.png')!r}, "roughness": 0.5,
                                          "metallic": 0.0}}, {str(tmp_path / 'light.exr')!r}, camera, samples=32)
        render_passes(objects, {str(tmp_path)!r})
    """)
    obj = read_image(tmp_path / "object.exr")
    with_shadow, without = read_image(tmp_path / "floor_with.exr"), read_image(tmp_path / "floor_without.exr")
    alpha = obj[..., 3]
    matte = np.clip(np.where(without[..., :3] > 0, with_shadow[..., :3] / np.maximum(without[..., :3], 1e-9), 1.0), 0, 1)
    cycles = linear_to_srgb(np.clip(obj[..., :3] + (1 - alpha[..., None]) * srgb_to_linear(photo) * matte, 0, 1))

    a, b = mitsuba.alpha > 0.5, alpha > 0.5
    iou = (a & b).sum() / (a | b).sum()
    free = (mitsuba.alpha < 0.01) & (alpha < 0.01)
    m_matte, c_matte = mitsuba.matte.mean(-1), matte.mean(-1)
    shadow = free & ((m_matte < 0.95) | (c_matte < 0.95))
    correlation = float(np.corrcoef(m_matte[shadow], c_matte[shadow])[0, 1])
    psnr = image_psnr(mitsuba.composite_srgb, cycles)
    print("CROSSCHECK", json.dumps({"iou": float(iou), "shadow_correlation": correlation, "psnr_db": psnr}))
    assert shadow.sum() > 100
    assert iou >= MIN_IOU and correlation >= MIN_SHADOW_CORRELATION and psnr >= MIN_PSNR_DB, (iou, correlation, psnr)
    # The red half of the texture lands on the same pixels in both renders (UV conventions agree).
    # (linear object layers: the sunlit side clips to white in the 8-bit composite)
    red_m, red_c = [(img[..., 0] > 1.5 * img[..., 2]) & a & b for img in (mitsuba.object_rgb, obj[..., :3])]
    assert red_m.sum() > 50 and (red_m & red_c).sum() / (red_m | red_c).sum() > 0.9
