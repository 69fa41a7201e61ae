"""The adapt stage's global views: the asset in the photo exactly as the compose stage puts it there.

core/stages/compose.py holds the one definition of the photo camera, the placement on the floor, the shadow
matte and the compositing rule; this module only renders the asset through that camera with the
current (differentiable) texture. What the inpainting critic scores is therefore what
`scenefit compose` would show for this texture, within sampling noise.

For a view that samples azimuth a, the asset is turned by -a on its spot, so the photo camera sees the
side the local view sees (the paper alpha-blends the rendering from the sampled camera into the photo).
The asset is rendered unmoved, with the photo camera moved into its frame; one window of the photo
(the union of the asset's boxes over all sampled turns) is rendered at the stage's render size.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import torch

from ..compose import ComposeConfig, ComposeInputs, shadow_matte
from ...scene.asset_pose import (ObjectPlacement, envmap_in_object_frame, photo_camera_in_object_frame,
                                place_asset)
from ...data.mesh import Mesh, normalize_to_unit_sphere
from ...render.loop_renderer import asset_renderer
from ...render.renderer import SceneOptions, WindowCamera
from ...scene.camera import PhotoCamera
from ...scene.placement import Placement


@dataclass
class GlobalRender:
    """One view's asset layer in the photo."""

    rgb: torch.Tensor                            # (h, w, 3) premultiplied linear radiance, differentiable
    alpha: torch.Tensor                          # (h, w, 1) coverage, differentiable
    rect: tuple[float, float, float, float]      # x0, y0, width, height of the layer in photo pixels
    matte: np.ndarray                            # (H, W, 3) the turned asset's shadow matte (no gradient)


def turn_for_azimuth(azimuth_deg: float) -> float:
    """The turn about Z that shows the photo camera the side an orbit camera at `azimuth_deg` sees."""
    return float(-azimuth_deg % 360.0)


def placement_turns(azimuths) -> list[float]:
    """The distinct turns the asset is placed at for orbit cameras at `azimuths` (degrees)."""
    return sorted({turn_for_azimuth(a) for a in azimuths})


class GlobalScene:
    """The photo, its camera and the asset placed in it; renders a view's asset layer and shadow."""

    def __init__(self, mesh: Mesh, maps_shape: tuple[int, int], photo: np.ndarray, placement: Placement,
                 camera: PhotoCamera, envmap: np.ndarray, azimuths: list[float], max_depth: int,
                 shadow_type: str, shadow_spp: int, seed: int = 0, renderer_type: str = "path") -> None:
        h, w = photo.shape[:2]
        # As ComposeJob does, so both place exactly the same mesh.
        self.mesh, _ = normalize_to_unit_sphere(mesh)
        self.photo = photo
        self.camera = replace(camera, width=w, height=h)
        self.pixel = placement.pixel((h, w))
        self.envmap = np.asarray(envmap, np.float32)
        self.compose_config = ComposeConfig(size=placement.size, shadow_type=shadow_type, spp=shadow_spp,
                                            denoiser_type="auto",
                                            max_depth=max_depth, seed=seed)
        self.placements: dict[float, ObjectPlacement] = {
            turn: place_asset(self.mesh, self.camera, self.pixel, placement.size, turn)
            for turn in placement_turns(azimuths)}
        boxes = np.array([p.pixel_box for p in self.placements.values()])
        self.window = (int(boxes[:, 0].min()), int(boxes[:, 1].min()), int(boxes[:, 2].max()), int(boxes[:, 3].max()))
        self.renderer = asset_renderer(renderer_type, self.mesh, maps_shape, self.envmap,
                                       SceneOptions(max_depth=max_depth, hide_emitters=True))
        self._mattes: dict[float, np.ndarray] = {}

    @property
    def box(self) -> tuple[float, float, float]:
        """(x0, y0, side): the square around the rendered window, which every global crop must hold."""
        x0, y0, x1, y1 = self.window
        side = float(max(x1 - x0, y1 - y0))
        return (x0 + x1 - side) / 2, (y0 + y1 - side) / 2, side

    def matte(self, turn: float) -> np.ndarray:
        """The shadow matte of the asset turned by `turn`, from compose's floor passes; cached per turn.

        No gradient: the asset is black in the floor passes, so the matte depends on its shape, place and
        the light, never on the texture being optimised (and the base light: a view's random
        spherical-Gaussian light, if any, changes the asset's shading but not this matte).
        """
        if turn not in self._mattes:
            # (no texture: the floor passes render the asset black)
            inputs = ComposeInputs(self.mesh, None, self.photo, self.pixel, self.envmap, self.camera,  # type: ignore[arg-type]
                                   turn)
            self._mattes[turn], _ = shadow_matte(inputs, self.compose_config)
        return self._mattes[turn]

    def camera_for(self, turn: float, size: int) -> tuple[WindowCamera, tuple[float, float, float, float]]:
        """The photo camera in the asset's frame, rendering the window at `size` px along its longer side;
        and the photo rectangle the rendered pixels cover."""
        h, w = self.photo.shape[:2]
        x0, y0, x1, y1 = self.window
        scale = size / max(x1 - x0, y1 - y0)
        film = (max(1, round(w * scale)), max(1, round(h * scale)))
        sx, sy = film[0] / w, film[1] / h
        cx0, cy0 = math.floor(x0 * sx), math.floor(y0 * sy)
        cx1, cy1 = min(math.ceil(x1 * sx), film[0]), min(math.ceil(y1 * sy), film[1])
        origin, forward, up = photo_camera_in_object_frame(self.camera, self.mesh, self.placements[turn])
        window = WindowCamera(tuple(origin), tuple(origin + forward), tuple(up), self.camera.fov_deg, film,
                              (cx0, cy0, cx1 - cx0, cy1 - cy0), self.camera.film_offset())
        return window, (cx0 / sx, cy0 / sy, (cx1 - cx0) / sx, (cy1 - cy0) / sy)

    def render(self, base_color: torch.Tensor, roughness: torch.Tensor, metallic: torch.Tensor,
               envmap: torch.Tensor, azimuth_deg: float, size: int, spp: int, seed: int) -> GlobalRender:
        """The asset (turned for `azimuth_deg`) through the photo camera, differentiable in the maps."""
        turn = turn_for_azimuth(azimuth_deg)
        matte = self.matte(turn)
        camera, rect = self.camera_for(turn, size)
        env = envmap_in_object_frame(envmap, self.placements[turn])
        out = self.renderer.render(camera, base_color, roughness, metallic, env, spp=spp, seed=seed)
        return GlobalRender(out.rgb, out.alpha, rect, matte)
