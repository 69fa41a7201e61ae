"""torch.distributed for the adapt stage: the paper's 4 views per step, one per GPU.

Launched by torchrun (`torchrun --nproc_per_node 4 -m scenefit.cli adapt ...`), each process
joins the group in `join_process_group`, renders its share of the step's views, and the texture's
and ε_ψ's gradients are summed over the ranks before each optimiser step. Each view's loss is
already weighted 1 / views_per_step, so the sum is the mean over the step's views on any number of
ranks. Without torchrun's environment (WORLD_SIZE unset or 1) nothing is joined.
"""
from __future__ import annotations

import os

import torch
import torch.distributed as dist

from ...base.decision import Decision


def rank_world() -> tuple[int, int]:
    if dist.is_available() and dist.is_initialized():
        return dist.get_rank(), dist.get_world_size()
    return 0, 1


def init_distributed(backend: str | None = None) -> tuple[int, int]:
    """Join the process group described by torchrun's environment (RANK, WORLD_SIZE, MASTER_ADDR...).

    nccl on CUDA, gloo otherwise; each rank uses GPU `LOCAL_RANK`. Returns (rank, world size).
    """
    if not dist.is_initialized():
        backend = backend or ("nccl" if torch.cuda.is_available() else "gloo")
        if torch.cuda.is_available():
            torch.cuda.set_device(int(os.environ.get("LOCAL_RANK", 0)))
        dist.init_process_group(backend)
    return dist.get_rank(), dist.get_world_size()


def join_process_group() -> tuple[int, int, Decision]:
    """(rank, world size, why): joins torchrun's group when launched by it, else runs alone."""
    if dist.is_available() and dist.is_initialized():
        rank, world = rank_world()
        return rank, world, Decision(world, "a process group was already initialised by the caller")
    if int(os.environ.get("WORLD_SIZE", "1")) > 1 and dist.is_available():
        rank, world = init_distributed()
        return rank, world, Decision(world, "launched by torchrun: joined its process group")
    return 0, 1, Decision(1, "one process (launch with torchrun to spread the views over several devices)")


def sum_gradients(params) -> None:
    """Sum each parameter's gradient over the ranks (no-op alone)."""
    if not (dist.is_available() and dist.is_initialized()):
        return
    for p in params:
        if p.grad is None:
            p.grad = torch.zeros_like(p)
        dist.all_reduce(p.grad, op=dist.ReduceOp.SUM)


def views_of_rank(views_per_step: int, rank: int, world: int) -> list[int]:
    """The step's view indices this rank renders (round robin)."""
    return list(range(rank, views_per_step, world))
