"""The add-on preferences: where models come from, the cache, offline, the device, where jobs run."""
import bpy
from bpy.app.translations import pgettext_iface as iface_
from bpy.props import BoolProperty, EnumProperty, StringProperty

# The add-on's own module name: `bl_ext.<repo>.scenefit` installed, `scenefit` in development.
ADDON_PACKAGE = __package__.rpartition(".")[0]

DEVICES = (
    ("auto", "Auto", "The GPU when torch sees one (NVIDIA's CUDA, else Apple's MPS), else the CPU"),
    ("cpu", "CPU", "Always the CPU"),
    ("cuda", "CUDA", "An NVIDIA GPU"),
    ("mps", "Apple GPU", "The GPU of an Apple silicon Mac (Metal Performance Shaders)"),
)

WORKER_TYPES = (
    ("LOCAL", "This Blender", "Jobs run inside Blender on its bundled (CPU) torch"),
    ("RAY", "Ray cluster", "Run All and Adapt go to a Ray cluster with GPUs (Ray must be importable in Blender)"),
    ("INSTALL", "SceneFit install", "Run All and Adapt go to another SceneFit install on this machine (e.g. one "
                                    "with CUDA torch), run by its Python"),
)
WORKER_WHEN = (
    ("ALWAYS", "Every Job", "Every Run All and Adapt goes to the worker"),
    ("ASK", "When Asked", "Jobs run in this Blender; long work asks first and offers Send to Worker"),
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
                                description="Folder for downloaded models. Empty: the Hugging Face cache "
                                            "(HF_HUB_CACHE or HF_HOME), so models other tools downloaded are used "
                                            "where they are, and stay when SceneFit is removed")
    offline: BoolProperty(name="Offline", default=False,
                          description="Never use the network: models must already be in the cache. Blender's "
                                      "'Allow Online Access' must also be on for any download")
    device: EnumProperty(name="Device", items=DEVICES, default="auto",
                         description="Where the diffusion and depth models run")
    attention_slicing: BoolProperty(name="Attention Slicing", default=False,
                                    description="Compute attention in pieces: less memory, a little slower. For "
                                                "GPUs with little memory and for Apple GPUs")
    vae_tiling: BoolProperty(name="VAE Tiling", default=False,
                             description="Encode and decode images in tiles: less memory for large images")
    cpu_offload: BoolProperty(name="CPU Offload", default=False,
                              description="Keep the models in the computer's memory and move each to the NVIDIA GPU "
                                          "only while it runs: far less GPU memory, slower")
    worker_type: EnumProperty(name="Run jobs on", items=WORKER_TYPES, default="LOCAL",
                              description="Where Run All and Adapt run; progress and previews come back to the panel")
    worker_when: EnumProperty(name="Send", items=WORKER_WHEN, default="ALWAYS",
                              description="Whether every Run All and Adapt goes to the worker, or only those you "
                                          "send from the question before long work")
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
        draw_models(layout.box(), context)
        row = layout.row()
        row.prop(self, "offline")
        row.prop(self, "device")
        col = layout.column(heading="Memory")
        col.prop(self, "attention_slicing")
        col.prop(self, "vae_tiling")
        if self.device in ("auto", "cuda"):
            col.prop(self, "cpu_offload")
        col = layout.column(heading="Jobs")
        col.prop(self, "worker_type")
        if self.worker_type == "RAY":
            col.prop(self, "ray_address")
        elif self.worker_type == "INSTALL":
            col.prop(self, "worker_python")
        if self.worker_type != "LOCAL":
            col.prop(self, "worker_when")
        col = layout.column(heading="Prompts")
        col.prop(self, "prompt_endpoint")
        col.prop(self, "prompt_model")
        col.prop(self, "prompt_api_key")
        if not bpy.app.online_access:
            layout.label(text="Blender's online access is off: models are only read from the cache.", icon="INFO")


def _size_words(state) -> str:
    from ..core.guidance import model_store as store

    if state.state in (store.FOUND, store.FOLDER):
        return store.format_bytes(state.bytes_on_disk)
    about = f"about {store.format_bytes(state.about_bytes)}" if state.about_bytes else "size unknown"
    if state.state == store.PARTIAL:
        return f"{store.format_bytes(state.bytes_on_disk)} of {about}"
    return "missing" if state.state == store.FOLDER_INCOMPLETE else f"missing ({about})"


def preferences_of(context):
    return context.preferences.addons[ADDON_PACKAGE].preferences


def draw_models(box, context) -> None:
    """One row per model: found or missing, its size, Download / Remove / Open Folder, and where it is;
    offline, the sentence that says what to fetch and where to put it."""
    import textwrap

    from ..core.guidance import model_store as store
    from ..operators.prefs import offline
    from ..operators.models import downloading, model_states

    from ..core.base.errors import SceneFitError
    from ..operators.models import earlier_model_cache

    box.label(text="Models")
    earlier = earlier_model_cache()
    if earlier and not preferences_of(context).model_cache:
        row = box.row()
        row.label(text=iface_("An earlier SceneFit downloaded models into {}").format(earlier), icon="INFO")
        row.operator("scenefit.use_earlier_model_cache")
    try:
        states = model_states(context)
    except SceneFitError as error:   # a model setting above that names nothing
        box.label(text=str(error), icon="ERROR")
        return
    for state in states:
        here = state.state in (store.FOUND, store.FOLDER)
        row = box.row(align=True)
        row.label(text=state.label, icon="CHECKMARK" if here else "ERROR")
        row.label(text=_size_words(state))
        if not here and state.state != store.FOLDER_INCOMPLETE:
            op = row.operator("scenefit.download_model", text="Resume" if state.state == store.PARTIAL else "Download",
                              icon="IMPORT")
            op.model = state.key
        if state.removable:
            row.operator("scenefit.remove_model", text="", icon="TRASH").model = state.key
        row.operator("scenefit.open_model_folder", text="", icon="FILE_FOLDER").model = state.key
        col = box.column(align=True)
        col.scale_y = 0.7
        col.label(text=state.where or state.cache)
        if not here and (offline(context) or state.state == store.FOLDER_INCOMPLETE):
            for line in textwrap.wrap(state.fetch, 110, break_on_hyphens=False, break_long_words=False):
                col.label(text=line)
    job = downloading()
    if job is not None:
        row = box.row(align=True)
        row.progress(factor=job.state.fraction, type="BAR", text=job.state.message or job.name)
        row.operator("scenefit.cancel_job", text="", icon="X")


classes = (SceneFitPreferences,)
