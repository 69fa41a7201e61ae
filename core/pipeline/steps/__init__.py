"""Each built-in stage's work module (the registry's `Stage.work`): how the stage is configured for a run and
run. Each is loaded when its stage runs (core/pipeline/registry.Stage.module)."""
