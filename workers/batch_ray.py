"""Batch jobs on a Ray cluster: a pool of JobWorker actors, each with the CPUs, GPUs and memory a job needs.

Ray is optional (`pip install 'scenefit[ray]'`); nothing here imports it before it is asked for.
Actors rather than plain tasks because Ray ends a GPU task's worker process after one call by
default, which would reload the diffusion models for every job; an actor keeps them.
"""
from __future__ import annotations

import math

from .batch import Dispatcher
from .job_worker import JobWorker, job_threads
from .payload import JobPayload
from ..core.base.errors import InputError
from .jobs import BatchSettings


def import_ray():
    try:
        import ray
    except ImportError:
        raise InputError("Ray is not installed; install it with `pip install 'scenefit[ray]'` "
                         "(or run without --ray to run the jobs here, one after another).") from None
    return ray


def ray_available() -> bool:
    try:
        import ray  # noqa: F401
    except ImportError:
        return False
    return True


def connect(mode: str, where_else: str = "", **init_options) -> bool:
    """Join or start Ray: "auto" (a running cluster, else a local one), "local" (always a new local
    one) or a cluster address ("ray://head:10001", "head:6379"). Returns True when this call started
    the connection (and so should shut it down). where_else: the caller's other choice, for the
    sentence an unreadable address gets."""
    ray = import_ray()
    if ray.is_initialized():
        return False
    address = None if mode == "auto" else mode
    try:
        ray.init(address=address, include_dashboard=False, log_to_driver=False, **init_options)
    except ConnectionError as error:
        raise InputError(f"Cannot reach the Ray cluster at '{mode}': {error}.") from None
    except ValueError as error:   # Ray's own "Invalid address format" (e.g. --ray none), a traceback before
        if "address" not in str(error).lower():
            raise
        raise InputError(f"'{mode}' is not a Ray cluster address; give auto, local, HOST:PORT or "
                         f"ray://HOST:PORT{where_else}.") from None
    return True


def job_resources(settings: BatchSettings, cluster: dict) -> dict:
    """Ray options for one job: GPUs ("auto": one when the cluster has any), CPUs, memory in bytes."""
    gpus = settings.num_gpus
    if gpus == "auto":
        gpus = 1.0 if cluster.get("GPU", 0) >= 1 else 0.0
    if gpus > 0 and cluster.get("GPU", 0) < gpus:  # type: ignore[operator]
        raise InputError(f"Each job asks for {gpus:g} GPU(s) but the Ray cluster has {cluster.get('GPU', 0):g}; "
                         f"set num_gpus in the jobs file's [batch] table.")
    if cluster.get("CPU", 0) < settings.num_cpus:
        raise InputError(f"Each job asks for {settings.num_cpus:g} CPU(s) but the Ray cluster has "
                         f"{cluster.get('CPU', 0):g}; set num_cpus in the jobs file's [batch] table.")
    options = {"num_cpus": settings.num_cpus, "num_gpus": gpus}
    if settings.memory_gb is not None:
        options["memory"] = int(settings.memory_gb * 2**30)
    return options


def worker_count(settings: BatchSettings, options: dict, cluster: dict, jobs: int) -> int:
    """As many workers as the cluster holds at once (or [batch] workers), never more than jobs."""
    if settings.workers is not None:
        return max(1, min(settings.workers, jobs))
    fits = [cluster.get("CPU", 0) / options["num_cpus"]]
    if options["num_gpus"] > 0:
        fits.append(cluster.get("GPU", 0) / options["num_gpus"])
    if "memory" in options and cluster.get("memory"):
        fits.append(cluster["memory"] / options["memory"])
    return max(1, min(jobs, math.floor(min(fits))))


class RayDispatcher(Dispatcher):
    """Jobs to a pool of JobWorker actors; a worker that dies is replaced and its job counts as failed."""

    def __init__(self, settings: BatchSettings, jobs: int, worker_class=JobWorker) -> None:
        ray = import_ray()
        self.ray = ray
        cluster = ray.cluster_resources()
        self.options = job_resources(settings, cluster)
        self.workers = worker_count(settings, self.options, cluster, jobs)
        self.actor_class = ray.remote(worker_class).options(**self.options)
        self.threads = job_threads(settings)
        self.idle = [self.actor_class.remote(threads=self.threads) for _ in range(self.workers)]
        self.queue: list[JobPayload] = []
        self.running: dict = {}   # ObjectRef -> (actor, payload)

    def submit(self, payload: JobPayload) -> None:
        self.queue.append(payload)
        self._start()

    def _start(self) -> None:
        while self.queue and self.idle:
            actor, payload = self.idle.pop(0), self.queue.pop(0)
            self.running[actor.run.remote(payload)] = (actor, payload)

    def next_done(self):
        ready, _ = self.ray.wait(list(self.running), num_returns=1)
        ref = ready[0]
        actor, payload = self.running.pop(ref)
        try:
            result = self.ray.get(ref)
        except self.ray.exceptions.RayActorError as error:   # the worker process died: start another
            self.ray.kill(actor)
            actor = self.actor_class.remote(threads=self.threads)
            result = error
        except Exception as error:   # the job raised: the worker is fine and takes the next one
            result = error
        self.idle.append(actor)
        self._start()
        return payload, result

    def close(self) -> None:
        for actor in self.idle + [a for a, _ in self.running.values()]:
            self.ray.kill(actor)
        self.idle, self.running = [], {}


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("", 0))
        return s.getsockname()[1]


class _Rank:
    """One process of a torch.distributed group started by Ray (what torchrun would start)."""

    def address(self) -> tuple[str, int]:
        import ray

        return ray.util.get_node_ip_address(), _free_port()

    def run(self, rank: int, world: int, master: tuple[str, int], local_rank: int, function, args: tuple):
        import os

        import torch.distributed as dist

        os.environ.update(RANK=str(rank), WORLD_SIZE=str(world), LOCAL_RANK=str(local_rank),
                          LOCAL_WORLD_SIZE=str(world), MASTER_ADDR=master[0], MASTER_PORT=str(master[1]))
        try:
            return function(*args)
        finally:
            if dist.is_available() and dist.is_initialized():
                dist.destroy_process_group()
            for key in ("RANK", "WORLD_SIZE", "LOCAL_RANK", "LOCAL_WORLD_SIZE", "MASTER_ADDR", "MASTER_PORT"):
                os.environ.pop(key, None)


def run_on_ranks(function, args: tuple, world: int, num_gpus_per_rank: float = 0.0,
                 num_cpus_per_rank: float = 1.0) -> list:
    """`function(*args)` on `world` Ray processes of one node, with torchrun's environment set, so the
    adapt stage's `join_process_group` joins them into one torch.distributed group (nccl on GPUs,
    gloo on CPUs): the paper's 4 views on 4 GPUs from a Ray task. Returns each rank's result.

    The ranks sit in one placement group packed onto one node. Ray shows each GPU actor only its
    own GPU, so every rank's LOCAL_RANK is 0 there (cuda:0 is its GPU); on CPUs it is the rank.
    """
    ray = import_ray()
    from ray.util.placement_group import placement_group, remove_placement_group
    from ray.util.scheduling_strategies import PlacementGroupSchedulingStrategy

    bundle = {"CPU": num_cpus_per_rank, **({"GPU": num_gpus_per_rank} if num_gpus_per_rank else {})}
    group = placement_group([bundle] * world, strategy="STRICT_PACK")
    try:
        ray.get(group.ready(), timeout=600)
        ranks = [ray.remote(_Rank).options(
            num_cpus=num_cpus_per_rank, num_gpus=num_gpus_per_rank,
            scheduling_strategy=PlacementGroupSchedulingStrategy(group, placement_group_bundle_index=i)).remote()
            for i in range(world)]
        master = ray.get(ranks[0].address.remote())
        results = ray.get([r.run.remote(i, world, master, 0 if num_gpus_per_rank else i, function, args)
                           for i, r in enumerate(ranks)])
        for r in ranks:
            ray.kill(r)
        return results
    finally:
        remove_placement_group(group)


__all__ = ["run_on_ranks", "RayDispatcher", "connect", "import_ray", "job_resources", "ray_available", "worker_count"]
