"""Thread vs child process for a SceneFit job (why operators/jobs.py runs jobs in a thread).

A 60-iteration conversion runs in a worker thread, then in a spawned child process, while the main
thread ticks every 50 ms as Blender's modal timer does; prints time to the first progress event,
total time and the main thread's tick gaps (a long gap is a frozen UI).

    python benchmarks/bench_jobs.py
"""
import multiprocessing as mp, time, threading, json, queue
import numpy as np
import tempfile

OUT = tempfile.mkdtemp(prefix="scenefit-bench-jobs-")

def job(progress):
    from scenefit.core.data.primitives import uv_sphere
    from scenefit.core.data.maps import PBRMaps
    from scenefit.core.pipeline.presets import stage_config
    from scenefit.core.stages.convert import convert_and_bake
    mesh = uv_sphere(segments=24, rings=12)
    rng = np.random.default_rng(0)
    maps = PBRMaps(base_color=rng.uniform(0.1, 0.9, (64, 64, 3)).astype(np.float32), roughness=0.5, metallic=0.0)
    convert_and_bake(mesh, maps, OUT, stage_config("convert", "draft", iterations=60), progress=progress)

def child(q):
    job(lambda e: q.put(("progress", e.step)))
    q.put(("done", None))

def drive(q):
    t0 = time.perf_counter(); first = None; gaps = []; last = t0
    while True:
        time.sleep(0.05)  # Blender's modal timer
        now = time.perf_counter(); gaps.append(now - last); last = now
        done = False
        while True:
            try: kind, _ = q.get_nowait()
            except queue.Empty: break
            if first is None: first = now - t0
            done |= kind == "done"
        if done: break
    return {"first_progress_s": round(first, 2), "total_s": round(time.perf_counter() - t0, 2),
            "max_tick_gap_s": round(max(gaps), 3), "median_tick_gap_s": round(float(np.median(gaps)), 3)}

if __name__ == "__main__":
    import torch, mitsuba  # what Blender holds once SceneFit has run
    q = queue.Queue()
    t = threading.Thread(target=lambda: (job(lambda e: q.put(("progress", e.step))), q.put(("done", None))), daemon=True)
    t.start(); thread = drive(q)
    ctx = mp.get_context("spawn"); pq = ctx.Queue()
    p = ctx.Process(target=child, args=(pq,)); p.start(); proc = drive(pq); p.join()
    print(json.dumps({"thread": thread, "process": proc}))
