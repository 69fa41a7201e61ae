"""The Write Prompt operator in a real bpy session, against the 127.0.0.1 chat server: the model's
prompt lands in the Style section (the instruction in edit mode), Blender's online-access switch
and the add-on's Offline switch give the template with no connection."""

import pytest

from conftest import printed_json
from conftest import ROOT

pytestmark = pytest.mark.blender

TESTS = ROOT / "tests"
DESCRIPTION = ("The leather sofa, partially submerged in the swamp, looks discolored and soggy, its once-polished "
               "surface marred by mud, moss, and the murky water of the swamp environment.")
INSTRUCTION = ("Soak the leather sofa, darken the leather with water stains, add mud to the legs, grow moss "
               "on the seams, fade the color.")


def test_write_prompt_operator(run_py, tmp_path):
    proc = run_py(f"""
        import json, sys
        sys.path.insert(0, {str(TESTS)!r})
        import bpy
        import addon_utils
        from chat_server import ChatServer, Reply

        bpy.ops.wm.read_factory_settings(use_empty=True)
        addon_utils.enable("scenefit", default_set=True)
        prefs = bpy.context.preferences.addons["scenefit"].preferences
        server = ChatServer([Reply("Mud and water.\\n\\nDescription: " + {DESCRIPTION!r}),
                             Reply("Water soaks it.\\n\\nInstructions: " + {INSTRUCTION!r})]).start()
        settings = bpy.context.scene.scenefit
        settings.object_prompt, settings.scene_prompt = "a leather sofa", "a swamp"
        out = {{}}
        def run(name):
            result = list(bpy.ops.scenefit.generate_prompt())
            out[name] = [result, settings.prompt, settings.instruction, settings.prompt_source, server.connections]

        bpy.context.preferences.system.use_online_access = False
        prefs.prompt_endpoint, prefs.prompt_model, prefs.prompt_api_key = server.url, "test-llm", "prefs-key"
        run("blender_offline")
        bpy.context.preferences.system.use_online_access = True
        prefs.offline = True
        run("addon_offline")
        prefs.offline = False
        run("online")
        settings.mode = "edit"
        run("edit")
        # The Style section draws the object, the scene, the button and the editable prompt (a
        # recording layout: panels cannot draw without a window).
        class Layout:
            drawn = []
            def column(self, **kw): return self
            def row(self, **kw): return self
            def prop(self, data, name, **kw): self.drawn.append([name, name in data.bl_rna.properties])
            def operator(self, idname, **kw): self.drawn.append([idname, hasattr(bpy.types, "SCENEFIT_OT_" + idname.split(".")[1])])
            def label(self, **kw): self.drawn.append(["label", True])
        from types import SimpleNamespace
        bpy.types.SCENEFIT_PT_style.draw(SimpleNamespace(layout=Layout()), bpy.context)
        out["style_section"] = Layout.drawn
        out["headers"] = {{k.lower(): v for k, v in server.requests[0]["headers"].items()}}
        out["edit_request"] = server.requests[-1]["body"]["messages"][0]["content"]
        server.stop()
        addon_utils.disable("scenefit")
        print("JSON" + json.dumps(out))
    """, env={"XDG_CACHE_HOME": str(tmp_path / "cache"), "SCENEFIT_CONFIG": str(tmp_path / "none.toml")})
    out = printed_json(proc)
    for name in ("blender_offline", "addon_offline"):
        result, prompt, _, source, connections = out[name]
        assert result == ["FINISHED"] and prompt == "a leather sofa in a swamp" and connections == 0
        assert source.startswith("Template (not model-written)")
    assert "online access is off" in out["blender_offline"][3] and "offline mode" in out["addon_offline"][3]
    result, prompt, _, source, connections = out["online"]
    assert result == ["FINISHED"] and prompt == DESCRIPTION and source == "Written by test-llm" and connections == 1
    assert out["headers"]["authorization"] == "Bearer prefs-key"
    result, prompt, instruction, _, _ = out["edit"]
    assert instruction == INSTRUCTION and prompt == DESCRIPTION          # edit mode fills the instruction
    assert "20 to 30 words" in out["edit_request"]
    drawn = [name for name, exists in out["style_section"] if exists]
    assert len(drawn) == len(out["style_section"])
    assert {"object_prompt", "scene_prompt", "scenefit.generate_prompt", "instruction", "label"} <= set(drawn)
