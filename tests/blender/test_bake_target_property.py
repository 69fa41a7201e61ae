"""Bake Asset's Target: the engine the file is for, handed to the same output settings as `--target`."""
from __future__ import annotations

import json

from conftest import printed_json


def test_bake_assets_target_chooses_what_that_engine_reads(run_py, tmp_path):
    document = {"asset": {"version": "2.0"}, "extensionsUsed": ["EXT_meshopt_compression", "KHR_materials_sheen"],
                "images": [{"uri": "a.webp", "mimeType": "image/webp"}], "meshes": []}
    (tmp_path / "in.gltf").write_text(json.dumps(document))
    out = printed_json(run_py(f"""
        import json
        from pathlib import Path
        from scenefit.core.base.errors import InputError
        from scenefit.operators.bake import AS_IMPORTED, SCENEFIT_OT_bake_asset, bake_output
        source = Path({str(tmp_path / "in.gltf")!r})
        from scenefit.operators import bake as module
        target = SCENEFIT_OT_bake_asset.__annotations__["target"]   # (a string: the module's annotations are)
        items = [item[0] for item in eval(target, vars(module)).keywords["items"]]
        out = {{"items": items}}
        for target in items:
            o = bake_output(AS_IMPORTED, AS_IMPORTED, 1024, "glb", source, False, target)
            out[target] = [o.compress, o.textures, sorted(o.extensions) if o.extensions is not None else None]
        try:
            bake_output("draco", AS_IMPORTED, 1024, "glb", source, False, "unreal")
        except InputError as error:
            out["refused"] = str(error)
        print("JSON" + json.dumps(out))
    """))
    assert out["items"] == ["as-imported", "web", "godot", "unity", "unreal"]
    assert out["as-imported"] == ["meshopt", "webp", None]
    assert out["web"][:2] == ["meshopt", "webp"] and "KHR_materials_sheen" in out["web"][2]
    assert out["godot"][:2] == ["none", "webp"] and "KHR_materials_sheen" not in out["godot"][2]
    assert out["unity"][:2] == ["none", "png"] and "EXT_texture_webp" not in out["unity"][2]
    assert out["unreal"][:2] == ["none", "png"] and "KHR_materials_sheen" in out["unreal"][2]
    assert out["refused"].startswith("Unreal Engine does not read draco compression")
