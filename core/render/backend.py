"""Starting Mitsuba: pick the variant at run time and find an LLVM that drjit can use.

Mitsuba's CPU variant JIT-compiles through a shared libLLVM >= 16 (with LLVM 15, drjit 1.5 aborts
inside LLVM). drjit looks for the library itself; DRJIT_LIBLLVM_PATH overrides it, and we set it to
the newest LLVM we find when the user has not, before mitsuba is first imported.
"""
from __future__ import annotations

import glob
import os
import platform
import re
from dataclasses import dataclass

from ..base.errors import RendererUnavailableError

MIN_LLVM_MAJOR = 16
_LLVM_GLOBS = (
    "/usr/lib/x86_64-linux-gnu/libLLVM*.so*",
    "/usr/lib/aarch64-linux-gnu/libLLVM*.so*",
    "/usr/lib/llvm-*/lib/libLLVM*.so*",
    "/usr/lib64/libLLVM*.so*",
    "/usr/local/lib/libLLVM*.so*",
    "/opt/homebrew/opt/llvm/lib/libLLVM.dylib",
    "/usr/local/opt/llvm/lib/libLLVM.dylib",
)


@dataclass(frozen=True)
class Backend:
    variant: str
    reason: str
    llvm_library: str | None

    @property
    def torch_device(self) -> str:
        """Where torch tensors must live to cross `dr.wrap`: it maps CUDA tensors to Dr.Jit's CUDA
        backend and CPU tensors to its LLVM one, and the two cannot mix in one scene."""
        return "cuda" if self.variant.startswith("cuda") else "cpu"


_active: Backend | None = None


def render_whole(mi, scene, integrator, **kwargs):
    """mi.render(scene, integrator=integrator, ...), or KeyboardInterrupt for a Ctrl-C during it: Mitsuba takes
    that Ctrl-C for itself, winds the render down and returns the partial image without an error, which
    must never pass for a finished one."""
    image = mi.render(scene, integrator=integrator, **kwargs)
    if integrator.should_stop():
        raise KeyboardInterrupt
    return image


def _llvm_major(path: str) -> int:
    numbers = [int(n) for n in re.findall(r"(?:LLVM[-.]?|llvm-)(\d+)", os.path.basename(path) + path)]
    return max(numbers) if numbers else 0


def find_llvm_library() -> str | None:
    """The newest libLLVM >= 16 on this machine, or None."""
    candidates = {p for pattern in _LLVM_GLOBS for p in glob.glob(pattern)}
    usable = [p for p in candidates if _llvm_major(p) >= MIN_LLVM_MAJOR]
    return max(usable, key=lambda p: (_llvm_major(p), len(p)), default=None)


def _cuda_usable() -> bool:
    try:
        import torch  # lazy: torch takes seconds to load; the CPU backend does without it

        return bool(torch.cuda.is_available())
    except Exception:  # torch missing or broken CUDA runtime: the CPU path still works
        return False


def init_mitsuba(prefer: str | None = None) -> Backend:
    """Select and activate the Mitsuba variant once per process; later calls return the same choice.

    prefer: "cuda_ad_rgb" or "llvm_ad_rgb" to force one; otherwise SCENEFIT_MITSUBA_VARIANT, then
    CUDA when torch sees a GPU, else LLVM.
    """
    global _active
    if _active is not None and (prefer is None or prefer == _active.variant):
        return _active

    llvm = os.environ.get("DRJIT_LIBLLVM_PATH")
    if not llvm:
        llvm = find_llvm_library()
        if llvm:
            os.environ["DRJIT_LIBLLVM_PATH"] = llvm

    import mitsuba as mi  # lazy: Mitsuba is heavy, and must load after DRJIT_LIBLLVM_PATH is set above

    requested = prefer or os.environ.get("SCENEFIT_MITSUBA_VARIANT")
    if requested:
        order, reason = [requested], f"requested ({requested})"
    elif _cuda_usable() and "cuda_ad_rgb" in mi.variants():
        order, reason = ["cuda_ad_rgb", "llvm_ad_rgb"], "CUDA is usable"
    else:
        order, reason = ["llvm_ad_rgb"], "no usable CUDA device, using the CPU (LLVM) backend"

    errors: list[str] = []
    for variant in order:
        try:
            mi.set_variant(variant)
            # Touch the JIT once so a missing/old LLVM fails here, with our message.
            import drjit as dr

            dr.eval(mi.Float(1.0) + 1.0)
            if variant != order[0]:
                reason = f"{order[0]} failed ({errors[-1]}); fell back to {variant}"
            _active = Backend(variant=variant, reason=reason, llvm_library=llvm)
            return _active
        except Exception as exc:  # try the next variant, then explain
            errors.append(f"{variant}: {exc}")
    hint = (
        f"Mitsuba's CPU backend needs a shared LLVM >= {MIN_LLVM_MAJOR} "
        "(on Debian/Ubuntu: apt-get install libllvm19), or set DRJIT_LIBLLVM_PATH to it."
    )
    raise RendererUnavailableError("Mitsuba could not start: " + "; ".join(errors) + ". " + hint)


def environment_info() -> dict:
    """The renderer, torch and the machine a report was made with."""
    import torch  # lazy: torch takes seconds to load; starting Mitsuba should not wait for it

    backend = init_mitsuba()
    return {
        "mitsuba_variant": backend.variant, "variant_reason": backend.reason,
        "llvm_library": backend.llvm_library, "torch": torch.__version__,
        "machine": f"{platform.machine()}, {torch.get_num_threads()} torch threads, {platform.platform()}",
    }
