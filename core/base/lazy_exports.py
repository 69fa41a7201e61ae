"""A package's names loaded from their modules when first asked for (PEP 562): a package whose modules load
torch hands out its names without loading torch when only a light module of it is imported.

    __getattr__, __dir__ = lazy_exports(__name__, globals(), {"NeuralTexture": "neural_texture", ...})
"""
from __future__ import annotations

import importlib
from typing import Any, Callable


def lazy_exports(package: str, namespace: dict[str, Any], module_of: dict[str, str]
                 ) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """The package's `__getattr__` (each name of `module_of` from its module, kept once loaded) and `__dir__`."""
    names = sorted(module_of)

    def getattr_(name: str) -> Any:
        if name not in module_of:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(f".{module_of[name]}", package), name)
        namespace[name] = value
        return value

    def dir_() -> list[str]:
        return names

    return getattr_, dir_
