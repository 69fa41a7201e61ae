"""Workers: what runs SceneFit's stages somewhere other than the caller's own call: the
thread job behind a Blender operator (background), the jobs file and batch runner (jobs, batch),
Ray (batch_ray) and remote workers (remote). They may load Blender files; core/ never does."""
