"""The model manager in a real bpy session, against a hub on 127.0.0.1 (tests/hub_server.py, a slow link):
Download as a background job (megabytes, speed, cancelled half-way through the job object, then resumed
by the operator), the Preferences' Models rows, Remove, Open Folder's target, the offline switch, and
the memory options reaching the models' settings."""
from pathlib import Path

import pytest

from conftest import printed_json

pytestmark = pytest.mark.blender

TESTS = Path(__file__).resolve().parents[1]


def test_download_cancel_resume_remove_in_blender(run_py, tmp_path):
    proc = run_py(f"""
        import json, os, sys, time
        from pathlib import Path
        sys.path.insert(0, {str(TESTS)!r})
        from hub_server import HubServer

        BIG = 23 * 1024 * 1024
        files = {{"unet/config.json": b'{{"u": 1}}', "unet/diffusion_pytorch_model.safetensors": os.urandom(BIG),
                 "vae/config.json": b'{{"v": 1}}', "vae/diffusion_pytorch_model.safetensors": b"v" * 2000,
                 "text_encoder/config.json": b'{{"t": 1}}', "text_encoder/model.safetensors": b"t" * 1000,
                 "tokenizer/vocab.json": b'{{"a": 1}}', "tokenizer/merges.txt": b"#m",
                 "scheduler/scheduler_config.json": b'{{"s": 1}}', "model_index.json": b'{{"i": 1}}'}}
        server = HubServer({{"tiny/sd2-base": files}}, seconds_per_mib=0.08).start()
        os.environ["HF_ENDPOINT"] = server.url      # read by huggingface_hub when it is first imported
        import bpy, addon_utils
        bpy.ops.wm.read_factory_settings(use_empty=True)
        addon_utils.enable("scenefit", default_set=True)
        from scenefit.operators import models as ops
        from scenefit.operators.prefs import model_settings
        from scenefit.workers import background
        out = {{}}
        prefs = bpy.context.preferences.addons["scenefit"].preferences
        prefs.base_model = "tiny/sd2-base"
        bpy.context.preferences.system.use_online_access = True
        out["default_cache"] = model_settings()[0].cache_dir
        prefs.model_cache = {str(tmp_path / "cache")!r}
        prefs.attention_slicing, prefs.cpu_offload, prefs.device = True, True, "cpu"
        models = model_settings()[0]
        out["memory"] = [models.attention_slicing, models.vae_tiling, models.cpu_offload, models.device_type]
        out["before"] = [s.state for s in ops.model_states()]

        name, data = ops.download_job(bpy.context, "base")
        job = background.start_job(background.Job(name, ops.download_work, data))
        out["poll_during"] = bpy.ops.scenefit.download_model.poll()
        seen = []
        while not job.state.finished:
            state = job.poll()
            if state.step and not state.finished:
                seen.append([state.step, state.total, state.message, state.status_line()])
            if state.step >= 8:
                job.cancel()
            time.sleep(0.05)
        out["cancelled"] = [job.state.status, seen[-1] if seen else None]
        background.release_job(job)
        out["after_cancel"] = [s.state for s in ops.model_states()]
        partial = list((Path({str(tmp_path / "cache")!r}) / "models--tiny--sd2-base" / "blobs").glob("*.incomplete"))
        out["partial_bytes"] = [p.stat().st_size for p in partial]

        server.requests.clear()
        out["resume"] = list(bpy.ops.scenefit.download_model(model="base"))
        out["ranges"] = [r["range"] for r in server.requests if r["method"] == "GET" and r["range"]]
        base = ops.model_states()[0]
        out["after_resume"] = [base.state, base.bytes_on_disk, base.where, ops.model_folder(bpy.context, "base")]

        class Layout:
            drawn = []
            scale_y = 1.0
            def box(self): return self
            def column(self, **kw): return self
            def row(self, **kw): return self
            def prop(self, data, name, **kw): self.drawn.append(["prop", name, name in data.bl_rna.properties])
            def operator(self, idname, **kw):
                self.drawn.append(["op", idname, kw.get("text"), hasattr(bpy.types, "SCENEFIT_OT_" + idname.split(".")[1])])
                return type("Op", (), {{}})()
            def label(self, **kw): self.drawn.append(["label", kw.get("text", "")])
            def progress(self, **kw): self.drawn.append(["progress", kw.get("text")])
        class Drawn:                     # the preferences as Blender draws them, into the recording layout
            layout = Layout()
            def __getattr__(self, name): return getattr(prefs, name)
        type(prefs).draw(Drawn(), bpy.context)
        out["drawn"] = Layout.drawn

        # an installed extension whose earlier version downloaded into its user folder: offered, not used unasked
        earlier = Path({str(tmp_path / "ext")!r}) / "models"
        (earlier / "models--stabilityai--stable-diffusion-2-base").mkdir(parents=True)
        bpy.utils.extension_path_user = lambda package, path="", create=False: str(earlier.parent / path)
        prefs.model_cache = ""
        Layout.drawn = []
        type(prefs).draw(Drawn(), bpy.context)
        out["earlier_offer"] = [d for d in Layout.drawn if d[0] == "op" and d[1] == "scenefit.use_earlier_model_cache"]
        out["earlier_cache_before"] = prefs.model_cache
        out["earlier_use"] = list(bpy.ops.scenefit.use_earlier_model_cache())
        out["earlier_cache"] = prefs.model_cache
        prefs.model_cache = {str(tmp_path / "cache")!r}

        out["remove"] = list(bpy.ops.scenefit.remove_model(model="base"))
        out["after_remove"] = [ops.model_states()[0].state, (Path({str(tmp_path / "cache")!r}) / "models--tiny--sd2-base").exists(),
                               ops.model_folder(bpy.context, "base")]
        bpy.context.preferences.system.use_online_access = False
        out["poll_offline"] = bpy.ops.scenefit.download_model.poll()
        Layout.drawn = []
        type(prefs).draw(Drawn(), bpy.context)
        out["drawn_offline"] = " ".join(d[1] for d in Layout.drawn if d[0] == "label")
        server.stop()
        addon_utils.disable("scenefit")
        print("JSON" + json.dumps(out))
    """, env={"HF_HUB_CACHE": str(tmp_path / "hf_default"), "HF_HUB_OFFLINE": "0"})
    out = printed_json(proc)
    assert out["default_cache"] is None     # no folder set: the Hugging Face cache itself
    assert out["memory"] == [True, False, True, "cpu"]
    assert out["before"] == ["missing", "missing", "missing"]
    assert out["poll_during"] is False      # one job at a time
    status, last = out["cancelled"]
    assert status == "cancelled" and last is not None
    step, total, message, line = last
    assert 8 <= step < total == 25 and "MB/s" in message and f"MB {step}/25" in line
    assert out["after_cancel"][0] == "partial" and len(out["partial_bytes"]) == 1 and out["partial_bytes"][0] > 0
    assert out["resume"] == ["FINISHED"] and out["ranges"] == [f"bytes={out['partial_bytes'][0]}-"]
    state, size, where, folder = out["after_resume"]
    assert state == "found" and size > 23 * 1024 * 1024 and where == folder and "snapshots" in where
    ops_drawn = [d for d in out["drawn"] if d[0] == "op"]
    assert all(d[3] for d in ops_drawn)     # every button is a registered operator
    base_buttons = [d[1] for d in ops_drawn][:3]
    assert base_buttons == ["scenefit.remove_model", "scenefit.open_model_folder", "scenefit.download_model"]
    assert sum(d[1] == "scenefit.download_model" for d in ops_drawn) == 2     # inpaint and depth are missing
    labels = [d[1] for d in out["drawn"] if d[0] == "label"]
    assert "Stable Diffusion 2 base" in labels and where in labels
    props = [d[1] for d in out["drawn"] if d[0] == "prop"]
    assert all(d[2] for d in out["drawn"] if d[0] == "prop")
    assert {"attention_slicing", "vae_tiling", "device", "model_cache"} <= set(props)
    assert "cpu_offload" not in props          # the device is the CPU: nothing to offload to
    assert len(out["earlier_offer"]) == 1 and out["earlier_offer"][0][3]
    assert out["earlier_cache_before"] == "" and out["earlier_use"] == ["FINISHED"]
    assert out["earlier_cache"] == str(tmp_path / "ext" / "models")
    assert out["remove"] == ["FINISHED"]
    assert out["after_remove"] == ["missing", False, str(tmp_path / "cache")]
    assert out["poll_offline"] is False
    # offline, each missing model says what to fetch and where to put it
    offline = out["drawn_offline"]
    assert "hf download tiny/sd2-base" in offline and "hf download stabilityai/stable-diffusion-2-inpainting" in offline
