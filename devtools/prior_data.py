"""The known-answer prior's training images, drawn with numpy: what the adapt stage's critics look at.

- local: one object (a union of rotated superellipses, lit softly) on grey or a random solid colour,
  as the local views show an asset (core/guidance/views.py local_view);
- global: the object in a photo-like picture (a tinted sky/ground split, soft noise, a few blocks, a
  shadow under the object), with the inpainting input the critic builds: the mask at latent size (1
  where the model paints, the object) and the picture with the object's pixels blanked to grey.

The object's colour follows devtools/known_prior.py: the prompt's colour word, else (global) the
picture's hue, else (local) any colour. Prompts use TRAIN_NOUNS and made-up words; HELD_OUT_NOUNS are
kept for the measurements, so those prompts are unseen.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .known_prior import COLOURS, hsv_to_rgb, scene_colour

SIZE = 32          # the prior's image side (its VAE halves it once: 16 x 16 latents)
TRAIN_NOUNS = ("chair", "table", "lamp", "vase", "car", "sofa", "bottle", "cup", "box", "ball", "stool", "bench",
               "bed", "desk", "clock", "kettle", "teapot", "boot", "hat", "bag", "plant", "pot", "robot", "dog",
               "cat", "bird", "horse", "house", "tower", "boat", "plane", "train", "bus", "bike", "sphere",
               "cube", "statue", "toy", "barrel", "crate", "shelf", "mug", "bowl", "rock", "tree", "bucket")
HELD_OUT_NOUNS = ("fox", "truck", "cabinet", "knight", "shoe", "helicopter", "character", "diorama",
                  "armchair", "milk truck", "toy car", "palm tree")
ADJECTIVES = ("", "small ", "old ", "wooden ", "shiny ", "metal ", "plastic ", "big ", "round ", "simple ")
SUFFIXES = ("", "", "", ", front view", ", side view", ", back view")
PLACES = ("", "", " in a room", " in a garden", " on the street", " in the photo")
_COLOURED = ("a {c} {a}{n}{p}", "{a}{n}, {c}", "a {a}{n}, {c}", "the {a}{n} painted {c}", "{c} {n}",
             "a photo of a {c} {n}{p}", "a {a}{n} that is {c}", "a {a}{n}{p}, {c}")
_PLAIN = ("a {a}{n}{p}", "{a}{n}", "a photo of a {a}{n}{p}", "the {a}{n}{p}", "a {a}{n}")


def vocabulary() -> tuple[str, ...]:
    """Every whole word of the training prompts but the made-up ones: the prior's tokenizer gives each one
    token, so a prompt is a few tokens and its colour word one of them."""
    text = " ".join([*TRAIN_NOUNS, *ADJECTIVES, *SUFFIXES, *PLACES, *_COLOURED, *_PLAIN, *COLOURS])
    return tuple(sorted({w for w in text.replace(",", " ").split() if w.isalpha()}))


def _noun(rng: np.random.Generator) -> str:
    if rng.uniform() < 0.4:   # a made-up word: the colour word must be read beside any noun
        letters = "abcdefghijklmnopqrstuvwxyz"
        return "".join(rng.choice(list(letters), int(rng.integers(3, 10))))
    return str(rng.choice(TRAIN_NOUNS))


def prompt_for(rng: np.random.Generator, colour: str | None) -> str:
    """A training prompt naming `colour` (None: no colour word), with a view suffix as generate mode adds."""
    fill = dict(a=str(rng.choice(ADJECTIVES)), n=_noun(rng), p=str(rng.choice(PLACES)))
    if colour is None:
        text = str(rng.choice(_PLAIN)).format(**fill)
    else:
        text = str(rng.choice(_COLOURED)).format(c=colour, **fill)
        if rng.uniform() < 0.1:   # an edit's object prompt with a colour of its own: the last word wins
            other = str(rng.choice([c for c in COLOURS if c != colour]))
            text = f"a {other} {fill['n']}, {colour}"
    return text + str(rng.choice(SUFFIXES))


def _srgb_to_linear(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)


def _linear_to_srgb(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.maximum(x, 0.0031308) ** (1 / 2.4) - 0.055)


def _object(rng: np.random.Generator, size: int, scale: float, centre: tuple[float, float]
            ) -> tuple[np.ndarray, np.ndarray]:
    """(alpha (size, size), shading (size, size)): a union of 1-3 rotated superellipses, drawn at 2x and
    averaged down (soft edges), and a soft light from one side (0.8-1.0, as an ambient-lit asset's)."""
    big = 2 * size
    ys, xs = (np.mgrid[0:big, 0:big] + 0.5) / big
    inside = np.zeros((big, big), bool)
    for k in range(int(rng.integers(1, 4))):
        cx = centre[0] + (0 if k == 0 else rng.uniform(-0.25, 0.25) * scale)
        cy = centre[1] + (0 if k == 0 else rng.uniform(-0.25, 0.25) * scale)
        a, b = scale * rng.uniform(0.25, 0.5), scale * rng.uniform(0.25, 0.5)
        p, angle = rng.uniform(1.6, 5.0), rng.uniform(0, np.pi)
        u = (xs - cx) * np.cos(angle) + (ys - cy) * np.sin(angle)
        v = -(xs - cx) * np.sin(angle) + (ys - cy) * np.cos(angle)
        inside |= (np.abs(u / a) ** p + np.abs(v / b) ** p) <= 1.0
    alpha = inside.reshape(size, 2, size, 2).mean(axis=(1, 3))
    direction = rng.normal(size=2)
    direction /= np.linalg.norm(direction) + 1e-9
    ys, xs = (np.mgrid[0:size, 0:size] + 0.5) / size
    ramp = ((xs - centre[0]) * direction[0] + (ys - centre[1]) * direction[1]) / max(scale, 1e-3)
    shading = np.clip(0.92 + 0.1 * ramp + rng.normal(0, 0.015, (size, size)), 0.75, 1.0)
    return alpha.astype(np.float32), shading.astype(np.float32)


def _smooth_noise(rng: np.random.Generator, size: int, cells: int, channels: int = 3) -> np.ndarray:
    import cv2  # (the project's image library)

    coarse = rng.normal(0, 1, (cells, cells, channels)).astype(np.float32)
    return cv2.resize(coarse, (size, size), interpolation=cv2.INTER_CUBIC).reshape(size, size, channels)


def photo_like(rng: np.random.Generator, size: int = SIZE) -> np.ndarray:
    """A tinted sRGB picture (size, size, 3): sky over ground around one hue, soft noise and a few blocks."""
    hue = rng.uniform(0, 360)
    sat = rng.uniform(0.15, 0.6)
    sky = np.array(hsv_to_rgb(hue + rng.uniform(-20, 20), sat * rng.uniform(0.5, 1.2), rng.uniform(0.5, 0.95)))
    ground = np.array(hsv_to_rgb(hue + rng.uniform(-25, 25), min(1.0, sat * rng.uniform(0.8, 1.5)),
                                 rng.uniform(0.25, 0.7)))
    horizon = rng.uniform(0.2, 0.7) * size
    ys = np.arange(size)[:, None, None] + 0.5
    blend = 1.0 / (1.0 + np.exp(-(ys - horizon) / rng.uniform(0.5, 3.0)))
    image = (1 - blend) * sky + blend * ground + np.zeros((1, size, 3))
    image = image + 0.06 * _smooth_noise(rng, size, int(rng.integers(2, 6)))
    for _ in range(int(rng.integers(0, 4))):   # blocks: furniture, buildings, trees
        x0, y0 = rng.integers(0, size, 2)
        w, h = rng.integers(2, size // 2, 2)
        tone = np.array(hsv_to_rgb(hue + rng.uniform(-40, 40), rng.uniform(0.05, 0.7), rng.uniform(0.15, 0.9)))
        image[y0:y0 + h, x0:x0 + w] = 0.3 * image[y0:y0 + h, x0:x0 + w] + 0.7 * tone
    image = image + rng.normal(0, 0.01, image.shape)
    return np.clip(image, 0.0, 1.0).astype(np.float32)


def _object_colour(rng: np.random.Generator, colour: str | None, scene: np.ndarray | None) -> np.ndarray:
    if colour is not None:
        base = np.array(COLOURS[colour])
    elif scene is not None:
        base = np.array(scene_colour(scene))
    else:   # no rule: any colour
        base = np.array(hsv_to_rgb(rng.uniform(0, 360), rng.uniform(0.0, 0.9), rng.uniform(0.1, 0.95)))
    return np.clip(base + rng.normal(0, 0.02, 3), 0.0, 1.0)


@dataclass
class Sample:
    image: np.ndarray            # (S, S, 3) sRGB in [0, 1]
    prompt: str
    mask: np.ndarray | None = None      # (S/2, S/2) 1 where the inpainting model paints (global only)
    masked: np.ndarray | None = None    # (S, S, 3) the picture with the object's pixels grey (global only)


def _colour_of_prompt(rng: np.random.Generator, p_colour: float) -> str | None:
    return str(rng.choice(list(COLOURS))) if rng.uniform() < p_colour else None


def local_sample(rng: np.random.Generator, size: int = SIZE, p_colour: float = 0.85) -> Sample:
    """An object on grey (half the time) or a random solid colour, as the local views show it."""
    colour = _colour_of_prompt(rng, p_colour)
    scale = rng.uniform(0.6, 1.0)
    centre = (0.5 + rng.uniform(-0.06, 0.06), 0.5 + rng.uniform(-0.06, 0.06))
    alpha, shading = _object(rng, size, scale, centre)
    background = np.array((0.5, 0.5, 0.5) if rng.uniform() < 0.5 else rng.uniform(0, 1, 3))
    linear = _srgb_to_linear(_object_colour(rng, colour, None)) * shading[..., None]
    image = alpha[..., None] * linear + (1 - alpha[..., None]) * _srgb_to_linear(background)
    return Sample(_linear_to_srgb(image).astype(np.float32), prompt_for(rng, colour))


def global_sample(rng: np.random.Generator, size: int = SIZE, p_colour: float = 0.5) -> Sample:
    """An object in a photo-like picture with its shadow, and the inpainting input for it."""
    colour = _colour_of_prompt(rng, p_colour)
    scene = photo_like(rng, size)
    scale = rng.uniform(0.25, 0.9)
    centre = (rng.uniform(0.5 * scale, 1 - 0.5 * scale), rng.uniform(0.5 * scale, 1 - 0.5 * scale))
    alpha, shading = _object(rng, size, scale, centre)
    ys, xs = (np.mgrid[0:size, 0:size] + 0.5) / size
    under = np.exp(-(((xs - centre[0]) / (0.45 * scale)) ** 2 + ((ys - centre[1] - 0.35 * scale) / (0.15 * scale)) ** 2))
    shadow = 1.0 - rng.uniform(0.2, 0.5) * under[..., None]
    linear = _srgb_to_linear(_object_colour(rng, colour, scene)) * shading[..., None]
    image = alpha[..., None] * linear + (1 - alpha[..., None]) * _srgb_to_linear(scene) * shadow
    image = _linear_to_srgb(image).astype(np.float32)
    covered = (alpha > 0.01).astype(np.float32)
    mask = covered.reshape(size // 2, 2, size // 2, 2).max(axis=(1, 3))   # as views.latent_mask (max pool)
    masked = image * (1 - covered[..., None]) + 0.5 * covered[..., None]   # as views.masked_image
    return Sample(image, prompt_for(rng, colour), mask.astype(np.float32), masked.astype(np.float32))
