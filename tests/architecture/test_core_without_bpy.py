"""core/ never imports bpy: import every core module with bpy made unimportable."""

from conftest import printed_json

from conftest import ROOT  # noqa: E402


def test_every_core_module_imports_without_bpy(run_py):
    modules = sorted(
        "scenefit." + ".".join(p.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__")
        for p in (ROOT / "core").rglob("*.py")
    )
    assert "scenefit.core.data.mesh" in modules and len(modules) > 5
    proc = run_py(f"""
        import importlib, json, sys

        class NoBpy:
            def find_spec(self, name, path=None, target=None):
                if name == "bpy" or name.startswith(("bpy.", "bmesh", "mathutils", "addon_utils")):
                    raise ImportError(f"{{name}} is blocked: core must not import Blender modules")
                return None

        sys.meta_path.insert(0, NoBpy())
        imported = []
        for name in {modules!r}:
            importlib.import_module(name)
            imported.append(name)
        import scenefit  # the package root must not import bpy either
        assert "bpy" not in sys.modules
        print("JSON" + json.dumps(imported))
    """)
    assert printed_json(proc) == modules


def test_blocker_really_blocks_bpy(run_py):
    """The finder above must make a bpy import fail, or the test proves nothing."""
    import pytest

    with pytest.raises(pytest.fail.Exception, match="blocked"):
        run_py("""
            import sys
            class NoBpy:
                def find_spec(self, name, path=None, target=None):
                    if name == "bpy":
                        raise ImportError("bpy is blocked")
            sys.meta_path.insert(0, NoBpy())
            import scenefit.operators  # imports bpy at module level
        """)
