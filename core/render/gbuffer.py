"""What a fixed camera sees of a fixed asset under a fixed light, traced once by Mitsuba: G-buffers.

For a view whose mesh, camera and light do not change, every sub-pixel sample hits the same surface
point: the same texels (indices and bilinear weights into the maps), the same shading normal (the
normal map applied), the same view direction, and the same visible environment. Only the texture's
values there change. `trace_gbuffer` records all of that with Mitsuba's ray tracer on the scene the
path tracer renders (core/render/renderer.py), plus the light terms the loop renderer shades with:

- `diffuse`: the cosine-weighted mean of the environment's radiance over the directions the point sees
  (occluded directions are dark): the diffuse lobe's light, visibility included;
- `specular[k]`: the mean radiance over the GGX lobe of roughness `levels[k]` about the mirror direction,
  visibility included (a pre-filtered environment with specular occlusion, as split-sum shading).

Light bounced between the asset's own surfaces is not modelled (it depends on the texture); the
agreement bench (benchmarks/bench_loop_render.py) measures what that costs against `path`.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import torch

from ..base.errors import InputError
from ..data.maps import FLAT_NORMAL
from ..data.materials import material_parts
from ..scene.frame import equirect_directions

LEVELS = (0.0, 0.2, 0.4, 0.6, 0.8, 1.0)   # roughness nodes of the specular light term


@dataclass(frozen=True)
class GBufferOptions:
    # Sub-pixel samples per pixel, stratified (a square number). Each reads the texture and is shaded on
    # its own: a pixel's textured detail (roughness and metallic shade non-linearly) needs 16; 4 cost
    # 7 dB against path tracing under ambient light, and averaging 4 texture lookups per sample won
    # back only 1.3 of them (benchmarks/FINDINGS.md, "The loop renderer under ambient light").
    samples: int = 16
    diffuse_rays: int = 4        # visibility rays per sample for the diffuse light term (64 per pixel)
    specular_rays: int = 4       # per sample and roughness level (the mirror level takes one)
    edge_samples: int = 16       # samples per pixel along the asset's edges (a square number)
    seed: int = 0
    # Under a light map (the global views) 4 samples of 16 diffuse rays agree with path tracing to >= 35 dB
    # on every corpus view (benchmarks/results/loop_render.md) at a sixth of 16 samples' shading time: the
    # map's own contrast, not the texture's detail inside a pixel, sets what the views show.
    map_samples: int = 4
    map_diffuse_rays: int = 16

    def __post_init__(self) -> None:
        for count in (self.samples, self.edge_samples):
            if round(count ** 0.5) ** 2 != count or count < 1:
                raise InputError(f"G-buffer samples per pixel must be square numbers, got {count}.")
        if min(self.diffuse_rays, self.specular_rays, self.map_diffuse_rays) < 1:
            raise InputError("G-buffers need at least one diffuse and one specular ray per sample.")
        if round(self.map_samples ** 0.5) ** 2 != self.map_samples or self.map_samples < 1:
            raise InputError(f"G-buffer samples per pixel must be square numbers, got {self.map_samples}.")

    def for_light(self, constant_light: bool) -> "GBufferOptions":
        """The settings a view lit by a constant light (the local views) or by a light map is traced with."""
        if constant_light:
            return self
        return replace(self, samples=self.map_samples, diffuse_rays=self.map_diffuse_rays)


# Samples traced in one go: each of Mitsuba's evaluations (one kernel, which Ctrl-C cannot stop) takes about a
# second at this size, where a 768-px view's 9.4 million in one kernel took 40 s; 256-px views (adapt's
# local views) fit in one chunk.
CHUNK_SAMPLES = 2**20


@dataclass
class GBuffer:
    """One view's cached samples. Hit samples only; `slots` says where each goes among the
    height x width pixels, and `share` how much of the pixel it stands for: the pixel's coverage
    (measured with many samples along edges) over its hit samples, so edges are anti-aliased as a
    path tracer's many samples make them."""

    height: int
    width: int
    samples: int
    slots: torch.Tensor          # (n,) int64: the pixel (row-major)
    share: torch.Tensor          # (n,) float32
    texels: torch.Tensor         # (n, 4) int32: flat indices into the maps (H * W) of the bilinear taps
    weights: torch.Tensor        # (n, 4) float32: their bilinear weights
    cosine: torch.Tensor         # (n,) float32: cos(shading normal, view); <= 0 shades black
    diffuse: torch.Tensor        # (n, C) float32, C = 1 (constant light) or 3
    specular: torch.Tensor       # (n, len(LEVELS), C) float32
    alpha: torch.Tensor          # (height, width, 1) float32: fraction of samples hitting the asset

    def to(self, device) -> "GBuffer":
        return GBuffer(self.height, self.width, self.samples,
                       *(t.to(device) for t in self.tensors()))

    def tensors(self) -> tuple[torch.Tensor, ...]:
        return (self.slots, self.share, self.texels, self.weights, self.cosine, self.diffuse, self.specular, self.alpha)

    def nbytes(self) -> int:
        return sum(t.element_size() * t.nelement() for t in self.tensors())


def bilinear_taps(uv: np.ndarray, size: tuple[int, int], mode: str) -> tuple[np.ndarray, np.ndarray]:
    """Mitsuba's bitmap lookup (filter bilinear): the four texels (x, y) read at `uv` (n, 2) of an image
    `size` (height, width) with wrap `mode`, and their weights. Returns ((n, 4, 2) int64, (n, 4))."""
    h, w = size
    x, y = uv[:, 0].astype(np.float64) * w - 0.5, uv[:, 1].astype(np.float64) * h - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = x - x0, y - y0
    xs = np.stack([x0, x0 + 1, x0, x0 + 1], 1).astype(np.int64)
    ys = np.stack([y0, y0, y0 + 1, y0 + 1], 1).astype(np.int64)
    weights = np.stack([(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy], 1)
    return np.stack([_wrap(xs, w, mode), _wrap(ys, h, mode)], -1), weights


def _wrap(index: np.ndarray, size: int, mode: str) -> np.ndarray:
    if mode == "clamp":
        return np.clip(index, 0, size - 1)
    if mode == "mirror":
        index = np.mod(index, 2 * size)
        return np.where(index < size, index, 2 * size - 1 - index)
    return np.mod(index, size)


def trace_gbuffer(renderer, camera, options: GBufferOptions, normal_map: np.ndarray | None,
                  envmap: np.ndarray, constant_light: bool,
                  prefiltered: "PrefilteredEnvironment | None" = None) -> GBuffer:
    """The G-buffer of `camera` in `renderer`'s scene (an AssetRenderer whose environment is already set
    to `envmap`, (He, We, 3) in the scene's latitude-longitude convention). `prefiltered`: that map's
    tables, where the caller keeps them across views (built here otherwise). Traced in chunks of
    CHUNK_SAMPLES, so a Ctrl-C stops it within seconds."""
    options = options.for_light(constant_light)
    scene, width, height = renderer.scene, camera.width, camera.height
    sensor = renderer._sensor(camera)
    rng = np.random.default_rng(options.seed)
    pixel, px, py = _sample_positions(scene, sensor, width, height, options, rng)
    if not constant_light and prefiltered is None:
        prefiltered = PrefilteredEnvironment(scene, envmap)
    chunks = [_traced_samples(renderer, sensor, px[at:at + CHUNK_SAMPLES], py[at:at + CHUNK_SAMPLES], options,
                              normal_map, rng, None if constant_light else prefiltered)
              for at in range(0, len(px), CHUNK_SAMPLES)]
    valid, part_of, texels, weights, cosine, diffuse, specular = (np.concatenate(arrays) for arrays in zip(*chunks))
    hits = np.flatnonzero(valid)
    order = np.argsort(part_of, kind="stable")
    taken = np.bincount(pixel, minlength=height * width)
    alpha = np.bincount(pixel, weights=valid, minlength=height * width) / np.maximum(taken, 1)
    pixel = pixel[hits]
    share = alpha[pixel] / np.bincount(pixel, minlength=height * width)[pixel]
    return GBuffer(height, width, options.samples, torch.from_numpy(pixel[order].astype(np.int64)),
                   torch.from_numpy(share[order].astype(np.float32)),
                   torch.from_numpy(texels[order].astype(np.int32)), torch.from_numpy(weights[order].astype(np.float32)),
                   torch.from_numpy(cosine[order].astype(np.float32)),
                   torch.from_numpy(diffuse[order].astype(np.float32)),
                   torch.from_numpy(specular[order].astype(np.float32)),
                   torch.from_numpy(alpha.reshape(height, width, 1).astype(np.float32)))


def _traced_samples(renderer, sensor, px: np.ndarray, py: np.ndarray, options: GBufferOptions, normal_map, rng,
                    prefiltered: "PrefilteredEnvironment | None") -> tuple[np.ndarray, ...]:
    """One chunk of the view's samples traced: (valid, and for the hits: part, texels, weights, cosine,
    diffuse, specular light), as numpy arrays."""
    # lazy: Mitsuba is heavy and Blender may lack it
    import drjit as dr
    import mitsuba as mi

    scene = renderer.scene
    ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(px, py), mi.Point2f(0.5, 0.5))
    si = scene.ray_intersect(ray)
    valid = np.array(si.is_valid(), bool)
    hits = np.flatnonzero(valid)
    si = dr.gather(mi.SurfaceInteraction3f, si, mi.UInt32(hits.astype(np.uint32)))
    part_of = _part_ids(scene, si, list(renderer.parts))
    uv = np.array(si.uv, np.float32).T
    texels, weights = _texel_taps(renderer, part_of, uv)
    frame = {name: np.array(v, np.float64).T for name, v in
             (("n", si.sh_frame.n), ("dp_du", si.dp_du), ("wi", -ray.d))}
    frame["wi"] = frame["wi"][hits]
    normal = _shading_normal(renderer, part_of, uv, frame, normal_map)
    cosine = np.sum(normal * frame["wi"], axis=1)
    diffuse, specular = _light_terms(scene, si, normal, frame["n"], frame["wi"], options, rng, prefiltered)
    return valid, part_of, texels, weights, cosine, diffuse, specular


def _sample_positions(scene, sensor, width: int, height: int, options: GBufferOptions, rng):
    """Each sample's pixel and film position: `samples` stratified ones per pixel, and
    `edge_samples` in the pixels along the asset's edges (found by a first probe: pixels whose
    samples disagree, and their neighbours), so edges are anti-aliased as a path tracer's are."""
    import mitsuba as mi  # lazy: Mitsuba is heavy and Blender may lack it

    def stratified(xs: np.ndarray, ys: np.ndarray, count: int):
        side = round(count ** 0.5)
        k = np.arange(count)
        u = rng.random((2, len(xs), count))
        px = (xs[:, None] + (k % side + u[0]) / side) / width
        py = (ys[:, None] + (k // side + u[1]) / side) / height
        return px.ravel().astype(np.float32), py.ravel().astype(np.float32)

    ys, xs = (a.ravel() for a in np.mgrid[0:height, 0:width])
    px, py = stratified(xs, ys, options.samples)
    probes = []
    for at in range(0, len(px), CHUNK_SAMPLES):
        ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(px[at:at + CHUNK_SAMPLES], py[at:at + CHUNK_SAMPLES]),
                                   mi.Point2f(0.5, 0.5))
        probes.append(np.array(scene.ray_test(ray), bool))
    hit = np.concatenate(probes).reshape(height, width, options.samples)
    cover = hit.mean(axis=2)
    band = (cover > 0) & (cover < 1)
    inside = cover > 0
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            band |= np.roll(np.roll(inside, dy, 0), dx, 1) != inside
    edge_count = max(options.samples, options.edge_samples)
    flat_band = band.ravel()
    ex, ey = stratified(xs[flat_band], ys[flat_band], edge_count)
    keep = np.repeat(~flat_band, options.samples)
    pixel = np.concatenate([np.repeat(np.flatnonzero(~flat_band), options.samples),
                            np.repeat(np.flatnonzero(flat_band), edge_count)])
    return pixel, np.concatenate([px[keep], ex]), np.concatenate([py[keep], ey])


def _part_ids(scene, si, shape_ids: list[str]) -> np.ndarray:
    """Each hit's material part (its index in `shape_ids`)."""
    # lazy: Mitsuba is heavy and Blender may lack it
    import drjit as dr
    import mitsuba as mi

    out = np.full(dr.width(si.t), -1, np.int64)
    for shape in scene.shapes():
        if shape.id() in shape_ids:
            mine = np.array(dr.eq(si.shape, mi.ShapePtr(shape)) if hasattr(dr, "eq") else si.shape == mi.ShapePtr(shape), bool)
            out[mine] = shape_ids.index(shape.id())
    if (out < 0).any():
        raise RuntimeError("A G-buffer sample hit a shape that is not one of the asset's parts.")
    return out


def _texel_taps(renderer, part_of: np.ndarray, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Flat map indices (into H x W) and weights of each sample's four bilinear taps, through its part's
    drawn texels (its cell, and the mirror copy Mitsuba draws for mixed wrap modes)."""
    h, w = renderer.maps_shape
    index_image = torch.arange(h * w, dtype=torch.float64).view(h, w, 1)
    texels, weights = np.zeros((len(uv), 4), np.int64), np.zeros((len(uv), 4))
    for i, piece in enumerate(renderer.parts.values()):
        mine = part_of == i
        drawn = _drawn_indices(piece, index_image)
        taps, wts = bilinear_taps(uv[mine], (int(drawn.shape[0]), int(drawn.shape[1])), piece.mode)
        texels[mine] = drawn[taps[..., 1], taps[..., 0]]
        weights[mine] = wts
    return texels, weights


def _drawn_indices(piece, index_image: torch.Tensor) -> np.ndarray:
    """The part's drawn texels as flat indices into the maps (DrawnPart.texels, applied to indices)."""
    cell = index_image[piece.part.rows, piece.part.cols]
    if piece.doubled is not None:
        cell = torch.cat([cell, torch.flip(cell, dims=[1 - piece.doubled])], dim=1 - piece.doubled)
    return cell[..., 0].numpy().astype(np.int64)


def _shading_normal(renderer, part_of, uv, frame, normal_map) -> np.ndarray:
    """The interpolated normal, perturbed by the tangent-space normal map as Mitsuba's `normalmap` BSDF
    does (its frame: the normal, and dp/du made orthogonal to it)."""
    n = frame["n"]
    if normal_map is None:
        return n
    out = n.copy()
    nm = torch.from_numpy(np.ascontiguousarray(normal_map, np.float32))
    normal_parts = {p.index: p for p in material_parts(renderer.mesh, tuple(nm.shape[:2]))}
    for i, piece in enumerate(renderer.parts.values()):
        cell = replace(piece, part=normal_parts[piece.part.index]).texels(nm).numpy()
        mine = np.flatnonzero(part_of == i)
        if np.allclose(cell, FLAT_NORMAL) or not len(mine):
            continue
        taps, wts = bilinear_taps(uv[mine], cell.shape[:2], piece.mode)
        local = np.einsum("nk,nkc->nc", wts, np.clip(cell, 0, 1)[taps[..., 1], taps[..., 0]]) * 2 - 1
        local /= np.maximum(np.linalg.norm(local, axis=1, keepdims=True), 1e-12)
        nn, du = n[mine], frame["dp_du"][mine]
        s = du - nn * np.sum(nn * du, axis=1, keepdims=True)
        s /= np.maximum(np.linalg.norm(s, axis=1, keepdims=True), 1e-12)
        t = np.cross(nn, s)
        out[mine] = local[:, :1] * s + local[:, 1:2] * t + local[:, 2:3] * nn
    return out / np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-12)


def _light_terms(scene, si, normal, shading, wi, options: GBufferOptions, rng,
                 prefiltered: "PrefilteredEnvironment | None"):
    """(n, C) diffuse and (n, levels, C) specular light at each hit (C = 1 for a constant environment:
    the fraction of the lobe that sees it). Under a map, each is the pre-filtered environment
    (core/render/gbuffer.py `PrefilteredEnvironment`, noise-free) times the fraction of the lobe's light
    the point sees, estimated from the traced rays (exactly 1 where nothing blocks the lobe).
    Directions below the interpolated normal are dark, as Mitsuba's `normalmap` BSDF makes them.
    `prefiltered` is None for a constant environment."""
    constant_light = prefiltered is None
    b1, b2 = _basis(normal)
    wi_local = np.stack([np.sum(wi * b1, 1), np.sum(wi * b2, 1), np.sum(wi * normal, 1)], 1)
    channels = 1 if constant_light else 3
    seen, total = np.zeros((len(normal), channels)), np.zeros((len(normal), channels))
    for j, u in enumerate(_sequence(options.diffuse_rays, len(normal), rng)):
        r, phi = np.sqrt(u[:, 0]), 2 * np.pi * u[:, 1]
        local = np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(np.maximum(0.0, 1 - u[:, 0]))], 1)
        visible, radiance = _seen(scene, si, local[:, :1] * b1 + local[:, 1:2] * b2 + local[:, 2:3] * normal,
                                  shading, constant_light)
        seen += visible * radiance
        total += radiance
    diffuse = _visible_share(seen, total, options.diffuse_rays)
    if prefiltered is not None:
        diffuse = diffuse * prefiltered.diffuse(normal)
    mirror = 2 * np.sum(wi * normal, 1, keepdims=True) * normal - wi
    specular = np.zeros((len(normal), len(LEVELS), channels))
    for k, roughness in enumerate(LEVELS):
        alpha = max(1e-3, roughness ** 2)
        seen, total, weights = (np.zeros((len(normal), channels)), np.zeros((len(normal), channels)),
                                np.zeros((len(normal), 1)))
        for u in _sequence(1 if roughness == 0 else options.specular_rays, len(normal), rng):
            m = _ggx_visible_normal(wi_local, alpha, u)
            wo = 2 * np.sum(wi_local * m, 1, keepdims=True) * m - wi_local
            weight = np.where(wo[:, 2] > 0, _smith_g1(wo, alpha), 0.0)[:, None]
            visible, radiance = _seen(scene, si, wo[:, :1] * b1 + wo[:, 1:2] * b2 + wo[:, 2:3] * normal, shading,
                                      constant_light)
            seen += weight * visible * radiance
            total += weight * radiance
            weights += weight
        specular[:, k] = _visible_share(seen, total, np.maximum(weights, 1e-12))
        if prefiltered is not None:
            specular[:, k] *= prefiltered.specular(_dominant(normal, mirror, roughness), roughness)
    return diffuse, specular


def _dominant(normal: np.ndarray, mirror: np.ndarray, roughness: float) -> np.ndarray:
    """Where a rough lobe's light mostly comes from: the mirror direction pulled towards the normal
    (Lagarde and de Rousiers 2014, "Moving Frostbite to PBR", the specular dominant direction)."""
    alpha = roughness ** 2
    smooth = 1.0 - alpha
    pull = smooth * (np.sqrt(smooth) + alpha)
    d = normal + pull * (mirror - normal)
    return d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)


def _visible_share(seen: np.ndarray, total: np.ndarray, count) -> np.ndarray:
    """The share of the lobe's light that arrives: seen / total where the lobe's rays met light, else
    the share of rays that were open (seen / count, with unit radiance)."""
    return np.where(total > 0, seen / np.where(total > 0, total, 1.0), seen / count)


class PrefilteredEnvironment:
    """The scene's environment convolved once with the cosine lobe and with GGX lobes about a mirror
    direction (split-sum's assumption: normal = view = mirror direction), on a latitude-longitude grid of
    directions; read bilinearly. The tables sum the map's texels (area-averaged to at most `texels`) by
    solid angle; the mirror level reads Mitsuba's own emitter (its orientation and filtering). Every view
    under the same map reads the same tables, so a renderer builds them once per map (LoopRenderer keeps
    them)."""

    def __init__(self, scene, envmap: np.ndarray, texels: tuple[int, int] = (64, 128),
                 grid: tuple[int, int] = (32, 64), levels: tuple[float, ...] = LEVELS) -> None:
        import cv2  # lazy: Blender may lack OpenCV (missing_modules)

        self.scene, self.grid = scene, grid
        env = np.asarray(envmap, np.float32)
        if env.shape[0] > texels[0]:   # area average: each coarse texel keeps its fine texels' light
            env = cv2.resize(env, (texels[1], texels[0]), interpolation=cv2.INTER_AREA)
        h, w = env.shape[:2]
        dirs = torch.from_numpy(equirect_directions(h, w).reshape(-1, 3).astype(np.float32))
        elevation = (0.5 - (np.arange(h) + 0.5) / h) * np.pi
        solid = torch.from_numpy(np.repeat(np.cos(elevation) * (np.pi / h) * (2 * np.pi / w), w).astype(np.float32))
        radiance = torch.from_numpy(env.reshape(-1, 3)) * solid[:, None]
        theta = (np.arange(grid[0]) + 0.5) / grid[0] * np.pi
        az = (np.arange(grid[1]) + 0.5) / grid[1] * 2 * np.pi
        t, a = np.meshgrid(theta, az, indexing="ij")
        nodes = torch.from_numpy(np.stack([np.sin(t) * np.cos(a), np.sin(t) * np.sin(a), np.cos(t)], -1)
                                 .reshape(-1, 3).astype(np.float32))
        rough = [r for r in levels if r > 0]
        diffuse, specular = torch.zeros(len(nodes), 3), torch.zeros(len(rough), len(nodes), 3)
        # float32 in blocks of nodes: the (nodes x texels) cosines of a 64 x 128 map at 32 x 64 nodes are
        # 16M numbers, shared by the cosine lobe and every GGX level.
        for start in range(0, len(nodes), 512):
            block = slice(start, start + 512)
            cos = nodes[block] @ dirs.T
            lit = cos.clamp(min=0)
            diffuse[block] = lit @ radiance / np.pi
            cos_h2 = ((1 + cos) / 2).clamp(min=0)
            lit_over_cos_h = lit / cos_h2.sqrt().clamp(min=1e-6)
            for k, roughness in enumerate(rough):
                a2 = max(1e-3, roughness ** 2) ** 2
                # D(h) (n.l) / (4 v.h) with n = v = the mirror direction: the lobe over directions l.
                weight = lit_over_cos_h / (cos_h2 * (a2 - 1) + 1) ** 2
                specular[k, block] = (weight @ radiance) / (weight @ solid).clamp(min=1e-30)[:, None]
        self._diffuse = diffuse.double().numpy().reshape(*grid, 3)
        self._specular = {r: specular[k].double().numpy().reshape(*grid, 3) for k, r in enumerate(rough)}

    def diffuse(self, normal: np.ndarray) -> np.ndarray:
        return self._read(self._diffuse, normal)

    def specular(self, mirror: np.ndarray, roughness: float) -> np.ndarray:
        if roughness == 0:   # a mirror: the radiance itself, as Mitsuba's emitter gives it
            return self._exact(mirror)
        if roughness not in self._specular:
            raise ValueError(f"No pre-filtered level for roughness {roughness}; built for {sorted(self._specular)}.")
        return self._read(self._specular[roughness], mirror)

    def _exact(self, d: np.ndarray) -> np.ndarray:
        return environment_radiance(self.scene, d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12))

    def _read(self, table: np.ndarray, d: np.ndarray) -> np.ndarray:
        h, w = self.grid
        unit = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
        y = np.arccos(np.clip(unit[:, 2], -1, 1)) / np.pi * h - 0.5
        x = (np.arctan2(unit[:, 1], unit[:, 0]) % (2 * np.pi)) / (2 * np.pi) * w - 0.5
        y0, x0 = np.floor(y), np.floor(x)
        fy, fx = (y - y0)[:, None], (x - x0)[:, None]
        ya, yb = np.clip(y0, 0, h - 1).astype(int), np.clip(y0 + 1, 0, h - 1).astype(int)
        xa, xb = (x0 % w).astype(int), ((x0 + 1) % w).astype(int)
        return ((1 - fy) * ((1 - fx) * table[ya, xa] + fx * table[ya, xb])
                + fy * ((1 - fx) * table[yb, xa] + fx * table[yb, xb]))


def _seen(scene, si, direction: np.ndarray, shading: np.ndarray, constant_light: bool):
    """Whether each hit sees the environment along `direction` ((n, 1): not blocked by the asset and
    above the interpolated normal), and the environment's radiance there ((n, 3); ones for a constant
    environment, (n, 1))."""
    import mitsuba as mi  # lazy: Mitsuba is heavy and Blender may lack it

    d = direction / np.maximum(np.linalg.norm(direction, axis=1, keepdims=True), 1e-12)
    d32 = mi.Vector3f(*np.ascontiguousarray(d.T, np.float32))
    blocked = np.array(scene.ray_test(si.spawn_ray(d32)), bool)
    visible = (~blocked & (np.sum(d * shading, 1) > 0)).astype(np.float64)[:, None]
    if constant_light:
        return visible, np.ones_like(visible)
    return visible, environment_radiance(scene, d)


def environment_radiance(scene, directions: np.ndarray) -> np.ndarray:
    """(n, 3) the scene's environment's radiance arriving from unit `directions` (n, 3), as Mitsuba's
    emitter gives it."""
    # lazy: Mitsuba is heavy and Blender may lack it
    import drjit as dr
    import mitsuba as mi

    lookup = dr.zeros(mi.SurfaceInteraction3f, len(directions))
    lookup.wi = -mi.Vector3f(*np.ascontiguousarray(np.asarray(directions).T, np.float32))
    return np.array(scene.environment().eval(lookup), np.float64).T


def _basis(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit tangents completing `n` (n, 3) to a frame (Duff et al.'s branchless construction)."""
    sign = np.where(n[:, 2] >= 0, 1.0, -1.0)
    a = -1.0 / (sign + n[:, 2])
    b = n[:, 0] * n[:, 1] * a
    b1 = np.stack([1 + sign * n[:, 0] ** 2 * a, sign * b, -sign * n[:, 0]], 1)
    b2 = np.stack([b, sign + n[:, 1] ** 2 * a, -n[:, 1]], 1)
    return b1, b2


def _sequence(count: int, n: int, rng):
    """`count` points of the R2 sequence in [0, 1)^2, shifted at random per sample (n, 2) each."""
    g = 1.32471795724474602596
    alpha = np.array([1 / g, 1 / g ** 2])
    shift = rng.random((n, 2))
    for j in range(count):
        yield (shift + (j + 0.5) * alpha) % 1.0


def _ggx_visible_normal(wi: np.ndarray, alpha: float, u: np.ndarray) -> np.ndarray:
    """A microfacet normal from GGX's distribution of normals visible from `wi` (Heitz 2018)."""
    v = np.stack([alpha * wi[:, 0], alpha * wi[:, 1], np.maximum(wi[:, 2], 1e-6)], 1)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    lensq = v[:, 0] ** 2 + v[:, 1] ** 2
    inv = np.where(lensq > 0, 1 / np.sqrt(np.maximum(lensq, 1e-30)), 0.0)
    t1 = np.where(lensq[:, None] > 0, np.stack([-v[:, 1] * inv, v[:, 0] * inv, np.zeros_like(inv)], 1),
                  np.array([1.0, 0.0, 0.0]))
    t2 = np.cross(v, t1)
    r, phi = np.sqrt(u[:, 0]), 2 * np.pi * u[:, 1]
    p1, p2 = r * np.cos(phi), r * np.sin(phi)
    s = 0.5 * (1 + v[:, 2])
    p2 = (1 - s) * np.sqrt(np.maximum(0.0, 1 - p1 ** 2)) + s * p2
    h = p1[:, None] * t1 + p2[:, None] * t2 + np.sqrt(np.maximum(0.0, 1 - p1 ** 2 - p2 ** 2))[:, None] * v
    m = np.stack([alpha * h[:, 0], alpha * h[:, 1], np.maximum(h[:, 2], 0.0)], 1)
    return m / np.maximum(np.linalg.norm(m, axis=1, keepdims=True), 1e-12)


def _smith_g1(w: np.ndarray, alpha: float) -> np.ndarray:
    cos2 = np.clip(w[:, 2] ** 2, 1e-12, 1.0)
    tan2 = (1 - cos2) / cos2
    return 2.0 / (1.0 + np.sqrt(1.0 + alpha ** 2 * tan2))
