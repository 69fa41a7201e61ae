"""Multi-resolution hash encoding in 3D (Müller et al. 2022, "Instant Neural Graphics Primitives").

Plain torch, so it runs on CPU and CUDA alike. Every level lives in one parameter tensor with
per-level row offsets, so the eight cell corners of all levels are indexed at once.

For fixed points (a texture's texels never move) the encoding is a *linear* map of the table:
features = A @ table with A a sparse (N*L, rows) matrix holding 8 trilinear weights per row.
`HashGrid3D.plan(points)` builds A once (and its transpose on the first backward); after that a
forward is one sparse-dense product and a backward another, which is several times faster on a
CPU than gathering and scatter-adding 8*L rows per point every iteration.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import torch
import torch.nn.functional as F

# The spatial hash of Instant-NGP: XOR of the integer corner coordinates times these primes.
HASH_PRIMES = (1, 2654435761, 805459861)


def level_resolutions(n_levels: int, base_resolution: int, finest_resolution: int) -> list[int]:
    """Grid resolution per level: a geometric progression from base to finest (Instant-NGP eq. 2-3)."""
    if n_levels == 1:
        return [int(base_resolution)]
    growth = math.exp((math.log(finest_resolution) - math.log(base_resolution)) / (n_levels - 1))
    return [int(math.floor(base_resolution * growth**level + 1e-6)) for level in range(n_levels)]


class HashGrid3D(torch.nn.Module):
    """Encode points in [0, 1]^3 as (N, n_levels * n_features) features.

    Level l has a grid of resolution R_l (cells per axis, so (R_l + 1)^3 vertices). Coarse levels
    whose vertices fit in the table are indexed densely (one row per vertex, no collisions); finer
    levels hash the vertex coordinates into a table of 2^log2_table rows.
    """

    def __init__(
        self,
        n_levels: int = 16,
        n_features: int = 2,
        log2_table: int = 19,
        base_resolution: int = 16,
        finest_resolution: int = 2048,
        init_scale: float = 1e-4,
    ) -> None:
        super().__init__()
        self.n_levels = int(n_levels)
        self.n_features = int(n_features)
        self.table_size = 1 << int(log2_table)
        self.resolutions = level_resolutions(self.n_levels, base_resolution, finest_resolution)

        sizes, dense = [], []
        for res in self.resolutions:
            vertices = (res + 1) ** 3
            dense.append(vertices <= self.table_size)
            sizes.append(vertices if dense[-1] else self.table_size)
        offsets = [0]
        for size in sizes[:-1]:
            offsets.append(offsets[-1] + size)
        # Dense levels come first because resolutions only grow; keep the split point.
        self.n_dense = sum(dense)
        self.level_sizes = sizes

        self.register_buffer("_res", torch.tensor(self.resolutions, dtype=torch.float32), persistent=False)
        self.register_buffer("_offsets", torch.tensor(offsets, dtype=torch.int64), persistent=False)
        # Per-level multipliers of the x, y, z vertex coordinate: dense strides or hash primes.
        mult = [
            (1, res + 1, (res + 1) ** 2) if is_dense else HASH_PRIMES
            for res, is_dense in zip(self.resolutions, dense)
        ]
        self.register_buffer("_mult", torch.tensor(mult, dtype=torch.int64), persistent=False)

        self.table = torch.nn.Parameter(torch.empty(sum(sizes), self.n_features, dtype=torch.float32))
        torch.nn.init.uniform_(self.table, -init_scale, init_scale)

    @property
    def output_dim(self) -> int:
        return self.n_levels * self.n_features

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """x: (N, 3) in [0, 1] (clamped). Returns (N, n_levels * n_features) float32."""
        if x.ndim != 2 or x.shape[1] != 3:
            raise ValueError(f"HashGrid3D expects points of shape (N, 3), got {tuple(x.shape)}.")
        n, levels = x.shape[0], self.n_levels
        with torch.no_grad():
            index, weight = self._corners(x.detach().to(torch.float32).clamp(0.0, 1.0))
        # One fused gather + weighted sum over the 8 corners of every (point, level) pair.
        features = F.embedding_bag(index, self.table, per_sample_weights=weight, mode="sum")
        return features.view(n, levels * self.n_features)

    def plan(self, x: torch.Tensor) -> "EncodingPlan":
        """Precompute the encoding of fixed points x (N, 3) in [0, 1] as a sparse matrix."""
        if x.ndim != 2 or x.shape[1] != 3:
            raise ValueError(f"HashGrid3D expects points of shape (N, 3), got {tuple(x.shape)}.")
        with torch.no_grad():
            index, weight = self._corners(x.detach().to(device=self.table.device, dtype=torch.float32).clamp(0.0, 1.0))
        return EncodingPlan(index=index.view(-1), weight=weight.view(-1), n_points=x.shape[0],
                            n_levels=self.n_levels, n_rows=self.table.shape[0])

    def forward_planned(self, plan: "EncodingPlan") -> torch.Tensor:
        """The encoding of the points a plan was built for: (N, n_levels * n_features)."""
        if plan.n_rows != self.table.shape[0] or plan.n_levels != self.n_levels:
            raise ValueError("This encoding plan was built for a hash grid of another shape.")
        features = _PlannedEncoding.apply(self.table, plan)
        return features.view(plan.n_points, self.output_dim)

    def _corners(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Table rows (N*L, 8) int64 and trilinear weights (N*L, 8) of every cell corner."""
        n, levels = x.shape[0], self.n_levels
        # Scaled coordinates per level: (N, L, 3); vertex coordinates are integers in [0, R_l].
        pos = x[:, None, :] * self._res[None, :, None]
        # The lower cell corner, kept one short of R_l so that x == 1 still has an upper corner.
        cell = torch.minimum(pos.floor(), (self._res - 1.0)[None, :, None])
        frac = pos - cell
        cell = cell.to(torch.int64)

        # Per axis, the (lower, upper) coordinate times that axis' multiplier: (N, L, 3, 2).
        corner = torch.stack((cell, cell + 1), dim=-1) * self._mult[None, :, :, None]
        cx, cy, cz = corner[:, :, 0], corner[:, :, 1], corner[:, :, 2]
        # Corner order (i, j, k) in {0,1}^3 with x slowest: broadcast to (N, L, 2, 2, 2).
        cx, cy, cz = cx[:, :, :, None, None], cy[:, :, None, :, None], cz[:, :, None, None, :]
        nd = self.n_dense
        parts = []
        if nd > 0:  # dense levels: linear index of the vertex
            parts.append(cx[:, :nd] + cy[:, :nd] + cz[:, :nd])
        if nd < levels:  # hashed levels: XOR of the prime products, modulo the table size
            parts.append((cx[:, nd:] ^ cy[:, nd:] ^ cz[:, nd:]) & (self.table_size - 1))
        index = parts[0] if len(parts) == 1 else torch.cat(parts, dim=1)
        index = (index + self._offsets[None, :, None, None, None]).view(n * levels, 8)

        wx = torch.stack((1.0 - frac[..., 0], frac[..., 0]), dim=-1)[:, :, :, None, None]
        wy = torch.stack((1.0 - frac[..., 1], frac[..., 1]), dim=-1)[:, :, None, :, None]
        wz = torch.stack((1.0 - frac[..., 2], frac[..., 2]), dim=-1)[:, :, None, None, :]
        weight = (wx * wy * wz).reshape(n * levels, 8)
        return index, weight


@dataclass(eq=False)
class EncodingPlan:
    """Sparse form of the encoding of fixed points: row p*L + l holds the 8 corner weights of point p, level l."""

    index: torch.Tensor  # (N*L*8,) int64 table rows
    weight: torch.Tensor  # (N*L*8,) float32 trilinear weights
    n_points: int
    n_levels: int
    n_rows: int
    _matrix: torch.Tensor | None = field(default=None, repr=False)
    _transposed: torch.Tensor | None = field(default=None, repr=False)

    def matrix(self) -> torch.Tensor:
        """A: (N*L, rows) CSR with 8 entries per row."""
        if self._matrix is None:
            m = self.n_points * self.n_levels
            crow = torch.arange(0, 8 * m + 1, 8, dtype=torch.int64, device=self.index.device)
            self._matrix = _csr(crow, self.index, self.weight, (m, self.n_rows))
        return self._matrix

    def transposed(self) -> torch.Tensor:
        """A^T: (rows, N*L) CSR, built on first use (a sort of all entries, a few seconds at 512^2)."""
        if self._transposed is None:
            order = torch.sort(self.index, stable=True).indices  # stable: columns ascend within a row
            counts = torch.bincount(self.index, minlength=self.n_rows)
            crow = torch.zeros(self.n_rows + 1, dtype=torch.int64, device=self.index.device)
            torch.cumsum(counts, 0, out=crow[1:])
            column = torch.div(order, 8, rounding_mode="floor")
            self._transposed = _csr(crow, column, self.weight[order], (self.n_rows, self.n_points * self.n_levels))
        return self._transposed


class _PlannedEncoding(torch.autograd.Function):
    """features = A @ table; d(table) = A^T @ d(features). No gradient for the points."""

    @staticmethod
    def forward(ctx, table: torch.Tensor, plan: EncodingPlan) -> torch.Tensor:  # noqa: D401
        ctx.plan = plan
        return plan.matrix() @ table

    @staticmethod
    def backward(ctx, grad: torch.Tensor):
        return ctx.plan.transposed() @ grad.contiguous(), None


def _csr(crow: torch.Tensor, column: torch.Tensor, value: torch.Tensor, size: tuple[int, int]) -> torch.Tensor:
    with warnings.catch_warnings():  # "sparse CSR support is in beta": we use only CSR @ dense.
        warnings.simplefilter("ignore", UserWarning)
        return torch.sparse_csr_tensor(crow, column, value, size=size, check_invariants=False)
