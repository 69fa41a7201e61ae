"""Views of the adapt stage spread over two processes with torch.distributed (gloo, CPU) by torchrun. Ray
launches the ranks with torchrun's environment (workers.batch_ray.run_on_ranks); that the adapt stage's
join and gradient sum work under it is test_batch_ray's test_ray_launches_a_torch_distributed_group_on_one_node.

Why the comparisons can be exact. Each view's loss is weighted 1/V and back-propagated on its own;
a rank accumulates its views' gradients in its own order and gloo sums the ranks' buffers. On one
Mitsuba thread (its gradient scatter uses atomic adds whose order varies across threads) and one
torch thread, every per-view gradient g_j is the same bits in whichever process computes it, so the
only difference is the order of the sums:
  one process, V views:     ((g0 + g1) + g2) + g3
  two ranks (round robin):  (g0 + g2) + (g1 + g3)
With two views, a + b = b + a holds exactly in IEEE arithmetic, so two ranks of one view each give
the bits of one process doing both, step after step. With four views the groupings differ, and
each ordering is within (V - 1) u sum|g_j| of the exact sum (u = 2^-24), so they differ by at most
2 (V - 1) u sum|g_j| per element: the test checks that bound, and that the distributed gradient is
exactly the rank-grouped sum. So the views here go through the models one at a time (batch_views
false): a rank's views in one batch would round differently from each alone (test_batched_views.py).
"""
from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import torch

pytestmark = pytest.mark.slow   # several processes (torchrun): what make test-quick leaves out

from scenefit.core.stages.adapt import AdaptConfig, AdaptInputs, AdaptSystem, StageSpec, adapt_texture  # noqa: E402
from scenefit.core.guidance import ModelConfig  # noqa: E402
from scenefit.core.scene.placement import Placement  # noqa: E402
from scenefit.core.pipeline.presets import stage_config  # noqa: E402
from scenefit.core.data.primitives import uv_sphere  # noqa: E402
from scenefit.core.data.uv_raster import rasterize_uv
from scenefit.core.texture import NeuralTexture  # noqa: E402

STAGES = (StageSpec(1.0, 16, 2, (30, 990)),)

# Run by each rank under torchrun.
RANK_SCRIPT = """
import sys, torch
sys.path.insert(0, {here!r})
from test_distributed import rank_work
result = rank_work({models!r})
if result["rank"] == 0:
    torch.save(result, {out!r})
"""


def rank_work(models: tuple[str, str]) -> dict:
    """One rank: a 4-views step (its gradients after the sum over ranks) and a 3-step 2-views run."""
    import drjit
    import torch.distributed as dist

    torch.set_num_threads(1)
    drjit.set_thread_count(1)
    inputs, four, two = setup(models)
    system = AdaptSystem.build(inputs, four)          # joins the launcher's group (gloo on CPU)
    system.step(0)
    grads = [p.grad.clone() for p in system.texture.parameters()]
    texture = adapt_texture(inputs, two).texture.state_dict()
    return {"rank": dist.get_rank(), "world": system.decisions()["world_size"].choice, "views": system.my_views,
            "grads": grads, "texture": texture}


def setup(models: tuple[str, str]):
    """Inputs, a 4-views-per-step config (one step) and a 2-views-per-step config (3 iterations)."""
    base, inpaint = models
    mesh = uv_sphere(segments=16, rings=8)
    raster = rasterize_uv(mesh, 32)
    texture = NeuralTexture(stage_config("texture", "draft", resolution=32, log2_table=12), seed=0)
    photo = np.random.default_rng(0).uniform(0.2, 0.8, (48, 64, 3)).astype(np.float32)
    inputs = AdaptInputs(mesh=mesh, raster=raster, texture=texture, photo=photo, placement=Placement((0.5, 0.6), 0.5))
    common = dict(prompt="a mossy sphere in a swamp", stages=STAGES, model_resolution=32, views=8, batch_views=False,
                  checkpoint_every=0, preview_every=0, lr_texture=1e-2,
                  models=ModelConfig(base_model=str(base), inpaint_model=str(inpaint)))
    return inputs, AdaptConfig(iterations=1, views_per_step=4, **common), AdaptConfig(iterations=3, views_per_step=2,
                                                                                        **common)


@pytest.fixture(scope="module")
def tiny_models():
    from conftest import shared_tiny_pair   # (here: the ranks import this module without the tests' path)

    return tuple(str(p) for p in shared_tiny_pair())


@pytest.fixture(scope="module")
def one_process(tiny_models):
    """Each of the 4 views' gradient alone at step 0, and the 3-step 2-views run, in this process."""
    import drjit

    threads = (torch.get_num_threads(), drjit.thread_count())
    torch.set_num_threads(1)
    drjit.set_thread_count(1)
    try:
        inputs, four, two = setup(tiny_models)
        system = AdaptSystem.build(inputs, four)
        per_view = []
        for j in range(4):
            system.optimizer.zero_grad(set_to_none=True)
            system.train_view(system.sample(0, j))
            per_view.append([p.grad.clone() for p in system.texture.parameters()])
        alone = adapt_texture(inputs, two)
    finally:
        torch.set_num_threads(threads[0])
        drjit.set_thread_count(threads[1])
    return per_view, alone.texture.state_dict()


def check_like_one_process(spread: dict, one_process) -> None:
    per_view, alone = one_process
    assert spread["world"] == 2 and spread["views"] == [0, 2]
    u = 2.0 ** -24
    for k, got in enumerate(spread["grads"]):
        g = [per_view[j][k] for j in range(4)]
        assert torch.equal(got, (g[0] + g[2]) + (g[1] + g[3]))          # rank 0's views, then rank 1's
        one = ((g[0] + g[1]) + g[2]) + g[3]
        assert torch.all((got - one).abs() <= 2 * 3 * u * sum(x.abs() for x in g))
    # Two views on two ranks: a + b = b + a, so the runs agree bit for bit over several steps.
    for name, value in alone.items():
        assert torch.equal(spread["texture"][name], value), name


def test_torchrun_two_gloo_ranks_average_view_gradients_like_one_process(tiny_models, one_process, tmp_path):
    out = tmp_path / "rank0.pt"
    script = tmp_path / "rank.py"
    script.write_text(textwrap.dedent(RANK_SCRIPT.format(here=str(Path(__file__).parent), models=tiny_models,
                                                         out=str(out))))
    proc = subprocess.run([sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node", "2",
                           str(script)], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-4000:]
    check_like_one_process(torch.load(out), one_process)
