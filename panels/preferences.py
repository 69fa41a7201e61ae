"""The add-on preferences: where models come from, the cache, offline, the device, where jobs run."""
import bpy
from bpy.props import BoolProperty, EnumProperty, StringProperty

# The add-on's own module name: `bl_ext.<repo>.scenefit` installed, `scenefit` in development.
ADDON_PACKAGE = __package__.rpartition(".")[0]

DEVICES = (
    ("auto", "Auto", "The GPU when torch sees one (CUDA), else the CPU"),
    ("cpu", "CPU", "Always the CPU"),
    ("cuda", "CUDA", "An NVIDIA GPU"),
)

WORKER_TYPES = (
    ("LOCAL", "This Blender", "Jobs run inside Blender on its bundled (CPU) torch"),
    ("RAY", "Ray cluster", "Run All and Adapt go to a Ray cluster with GPUs (Ray must be importable in Blender)"),
    ("INSTALL", "SceneFit install", "Run All and Adapt go to another SceneFit install on this machine (e.g. one "
                                    "with CUDA torch), run by its Python"),
)


class SceneFitPreferences(bpy.types.AddonPreferences):
    bl_idname = ADDON_PACKAGE

    base_model: StringProperty(name="Diffusion model", default="stabilityai/stable-diffusion-2-base",
                               description="Hub id or local folder of Stable Diffusion 2 base")
    inpaint_model: StringProperty(name="Inpainting model", default="stabilityai/stable-diffusion-2-inpainting",
                                  description="Hub id or local folder of Stable Diffusion 2 inpainting")
    depth_model: StringProperty(name="Depth model", default="depth-anything/Depth-Anything-V2-Small-hf",
                                description="Hub id or local folder of a transformers depth model")
    model_cache: StringProperty(name="Model cache", subtype="DIR_PATH", default="",
                                description="Folder for downloaded models (empty: 'models' in this extension's "
                                            "user folder)")
    offline: BoolProperty(name="Offline", default=False,
                          description="Never use the network: models must already be in the cache. Blender's "
                                      "'Allow Online Access' must also be on for any download")
    device: EnumProperty(name="Device", items=DEVICES, default="auto",
                         description="Where the diffusion and depth models run")
    worker_type: EnumProperty(name="Run jobs on", items=WORKER_TYPES, default="LOCAL",
                              description="Where Run All and Adapt run; progress and previews come back to the panel")
    ray_address: StringProperty(name="Ray address", default="local",
                                description="'local' starts a Ray cluster on this machine; else the cluster's "
                                            "address, e.g. ray://head:10001 (needs Blender's Allow Online Access)")
    worker_python: StringProperty(name="SceneFit Python", subtype="FILE_PATH", default="",
                                  description="The Python interpreter of a SceneFit install with CUDA torch "
                                              "(e.g. ~/scenefit/.venv/bin/python)")
    prompt_endpoint: StringProperty(name="Prompt endpoint", default="",
                                    description="OpenAI-compatible chat URL that writes prompts, e.g. "
                                                "http://127.0.0.1:8080/v1 (empty: the config file or OPENAI_BASE_URL; "
                                                "none: a simple template)")
    prompt_model: StringProperty(name="Prompt model", default="", description="Chat model name at that endpoint")
    prompt_api_key: StringProperty(name="API key", default="", subtype="PASSWORD",
                                   description="Key for the prompt endpoint (empty: OPENAI_API_KEY or the config file)")

    def draw(self, context):
        layout = self.layout
        layout.prop(self, "base_model")
        layout.prop(self, "inpaint_model")
        layout.prop(self, "depth_model")
        layout.prop(self, "model_cache")
        row = layout.row()
        row.prop(self, "offline")
        row.prop(self, "device")
        col = layout.column(heading="Jobs")
        col.prop(self, "worker_type")
        if self.worker_type == "RAY":
            col.prop(self, "ray_address")
        elif self.worker_type == "INSTALL":
            col.prop(self, "worker_python")
        col = layout.column(heading="Prompts")
        col.prop(self, "prompt_endpoint")
        col.prop(self, "prompt_model")
        col.prop(self, "prompt_api_key")
        if not bpy.app.online_access:
            layout.label(text="Blender's online access is off: models are only read from the cache.", icon="INFO")


classes = (SceneFitPreferences,)
