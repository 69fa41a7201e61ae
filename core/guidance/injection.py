"""Reference feature injection (paper §3.3, "Identity Preservation") as diffusers attention processors.

The UNet is called once on a batch [x_t rows..., x^r_t rows...]: the reference rows run the plain
UNet; in every injected self-attention layer the x_t rows attend to the keys and values of their
own tokens concatenated with those of their reference row:

    A(x_t, ·, x^r_t) = softmax(Q [K; K^r]^T / sqrt(d)) [V; V^r]

and the text-unconditional rows become s_c · A(x_t, ∅, ∅) + (1 - s_c) · A(x_t, ∅, x^r_t). Layer by
layer this equals running the reference through the UNet first and keeping its K^r, V^r, in one
pass. Which rows are which is set per call with `ReferenceInjector.layout(...)`; outside it the
processors are plain attention (the same code as diffusers' AttnProcessor2_0).
"""
from __future__ import annotations

import math
import re
from contextlib import contextmanager
from dataclasses import dataclass

import torch
import torch.nn.functional as F

from ..base.errors import InputError


@dataclass(frozen=True)
class Layout:
    """Rows of the batch: x rows are [0, n_x), reference row of x row i is n_x + ref_index[i];
    `uncond` lists the x rows of the text-unconditional branch."""

    n_x: int
    ref_index: tuple[int, ...]
    uncond: tuple[int, ...]
    control_scale: float


class _State:
    def __init__(self) -> None:
        self.layout: Layout | None = None


def _attention(attn, hidden_states: torch.Tensor, key_value_states: torch.Tensor | None = None,
               encoder_hidden_states: torch.Tensor | None = None, attention_mask=None, temb=None) -> torch.Tensor:
    """diffusers' AttnProcessor2_0, with self-attention keys/values taken from `key_value_states`
    (tokens of the rows themselves, possibly concatenated with reference tokens)."""
    residual = hidden_states
    if attn.spatial_norm is not None:
        hidden_states = attn.spatial_norm(hidden_states, temb)
    input_ndim = hidden_states.ndim
    if input_ndim == 4:
        batch, channel, height, width = hidden_states.shape
        hidden_states = hidden_states.view(batch, channel, height * width).transpose(1, 2)
        if key_value_states is not None:
            key_value_states = key_value_states.view(batch, channel, -1).transpose(1, 2)
    batch, _, _ = hidden_states.shape if encoder_hidden_states is None else encoder_hidden_states.shape
    seq = (encoder_hidden_states if encoder_hidden_states is not None else
           key_value_states if key_value_states is not None else hidden_states).shape[1]
    if attention_mask is not None:
        attention_mask = attn.prepare_attention_mask(attention_mask, seq, batch)
        attention_mask = attention_mask.view(batch, attn.heads, -1, attention_mask.shape[-1])
    if attn.group_norm is not None:
        hidden_states = attn.group_norm(hidden_states.transpose(1, 2)).transpose(1, 2)
        if key_value_states is not None:
            key_value_states = attn.group_norm(key_value_states.transpose(1, 2)).transpose(1, 2)
    query = attn.to_q(hidden_states)
    if encoder_hidden_states is not None:
        source = encoder_hidden_states
        if attn.norm_cross:
            source = attn.norm_encoder_hidden_states(source)
    else:
        source = key_value_states if key_value_states is not None else hidden_states
    key, value = attn.to_k(source), attn.to_v(source)
    inner_dim = key.shape[-1]
    head_dim = inner_dim // attn.heads
    query = query.view(batch, -1, attn.heads, head_dim).transpose(1, 2)
    key = key.view(batch, -1, attn.heads, head_dim).transpose(1, 2)
    value = value.view(batch, -1, attn.heads, head_dim).transpose(1, 2)
    if attn.norm_q is not None:
        query = attn.norm_q(query)
    if attn.norm_k is not None:
        key = attn.norm_k(key)
    hidden_states = F.scaled_dot_product_attention(query, key, value, attn_mask=attention_mask, dropout_p=0.0,
                                                   is_causal=False)
    hidden_states = hidden_states.transpose(1, 2).reshape(batch, -1, attn.heads * head_dim).to(query.dtype)
    hidden_states = attn.to_out[0](hidden_states)
    hidden_states = attn.to_out[1](hidden_states)
    if input_ndim == 4:
        hidden_states = hidden_states.transpose(-1, -2).reshape(batch, channel, height, width)
    if attn.residual_connection:
        hidden_states = hidden_states + residual
    return hidden_states / attn.rescale_output_factor


class PlainProcessor:
    """Attention exactly as diffusers' AttnProcessor2_0 (set on layers that are not injected, so one
    code path serves the injected and the plain UNet)."""

    def __call__(self, attn, hidden_states, encoder_hidden_states=None, attention_mask=None, temb=None, *args, **kwargs):
        return _attention(attn, hidden_states, None, encoder_hidden_states, attention_mask, temb)


class ReferenceProcessor:
    """Self-attention with reference keys/values for the rows a Layout names."""

    def __init__(self, state: _State) -> None:
        self.state = state

    def __call__(self, attn, hidden_states, encoder_hidden_states=None, attention_mask=None, temb=None, *args, **kwargs):
        layout = self.state.layout
        if layout is None or encoder_hidden_states is not None:
            return _attention(attn, hidden_states, None, encoder_hidden_states, attention_mask, temb)
        if attention_mask is not None:
            raise InputError("Reference injection does not support attention masks.")
        n = layout.n_x
        x, refs = hidden_states[:n], hidden_states[n:]
        ref_rows = refs[list(layout.ref_index)]
        token_dim = 1 if hidden_states.ndim == 3 else -1
        if hidden_states.ndim == 4:  # (B, C, H, W): concatenate flattened tokens
            b, c = x.shape[:2]
            kv = torch.cat([x.reshape(b, c, -1), ref_rows.reshape(b, c, -1)], dim=-1)
        else:
            kv = torch.cat([x, ref_rows], dim=token_dim)
        # Reference rows: the plain UNet (their own tokens only).
        out_ref = _attention(attn, refs, None, None, None, temb)
        out_x = _attention(attn, x, kv, None, None, temb)
        s_c = layout.control_scale
        if layout.uncond and s_c != 0.0:
            rows = list(layout.uncond)
            plain = _attention(attn, x[rows], None, None, None, temb)
            if s_c == 1.0:
                mixed = plain
            else:
                mixed = s_c * plain + (1.0 - s_c) * out_x[rows]
            out_x = out_x.clone()
            out_x[rows] = mixed
        return torch.cat([out_x, out_ref], dim=0)


_ORDER = {"down_blocks": 0, "mid_block": 1, "up_blocks": 2}


def self_attention_layers(unet) -> list[str]:
    """Processor names of the transformer blocks' self-attention (attn1), in the UNet's data order."""
    names = [n for n in unet.attn_processors if n.endswith("attn1.processor")]

    def key(name: str):
        part = name.split(".")[0]
        return (_ORDER.get(part, 3), [int(x) for x in re.findall(r"\.(\d+)\.", name)])

    return sorted(names, key=key)


class ReferenceInjector:
    """Installs the processors on a UNet; `fraction` (p) of its self-attention layers are injected.

    The first ceil(p x N) self-attention layers in data order (down blocks, middle, up blocks) are
    injected; the paper gives p, not which blocks.
    """

    def __init__(self, unet, fraction: float = 1.0) -> None:
        if not 0.0 <= fraction <= 1.0:
            raise InputError(f"The injected fraction p must be in [0, 1], got {fraction}.")
        self.state = _State()
        layers = self_attention_layers(unet)
        self.injected = layers[: math.ceil(fraction * len(layers) - 1e-9)]
        processors = {}
        for name in unet.attn_processors:
            processors[name] = ReferenceProcessor(self.state) if name in self.injected else PlainProcessor()
        unet.set_attn_processor(processors)
        self.fraction = fraction

    @contextmanager
    def layout(self, layout: Layout | None):
        previous = self.state.layout
        self.state.layout = layout
        try:
            yield
        finally:
            self.state.layout = previous
