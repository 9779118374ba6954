"""Time onnxruntime on a temc ONNX model: the reference side of benches/tract_vs_ort.rs.

    python scripts/bench_ort.py --model M.onnx --size 256 --threads 2 --reps 5

Two configurations per thread count, because onnxruntime has two ways to use N cores:
`intra` runs one image with N intra-op threads; `parallel` runs N images at once on N
sessions of one thread each (what temc does with tiles). Prints one JSON object per line.
"""

import argparse
import json
import threading
import time

import numpy as np
import onnxruntime as ort


def session(path: str, threads: int) -> ort.InferenceSession:
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = threads
    opts.inter_op_num_threads = 1
    opts.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    opts.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    return ort.InferenceSession(path, opts, providers=["CPUExecutionProvider"])


def feeds(sess: ort.InferenceSession, size: int) -> dict:
    out = {}
    for inp in sess.get_inputs():
        c = inp.shape[1]
        n = c * size * size
        # Same deterministic values as the Rust bench.
        v = 0.5 + 0.4 * np.sin(np.arange(n, dtype=np.float32) * np.float32(0.013))
        out[inp.name] = v.astype(np.float32).reshape(1, c, size, size)
    return out


def timed(run, reps: int) -> list:
    run()  # warm-up
    times = []
    for _ in range(reps):
        t = time.perf_counter()
        run()
        times.append(time.perf_counter() - t)
    return sorted(times)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--model", required=True)
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--reps", type=int, default=5)
    a = ap.parse_args()
    meta = session(a.model, 1).get_modelmeta().custom_metadata_map
    width = float(meta.get("temc.width", "nan"))

    configs = {"intra": (1, a.threads)}
    if a.threads > 1:
        configs["parallel"] = (a.threads, 1)
    for name, (images, intra) in configs.items():
        sessions = [session(a.model, intra) for _ in range(images)]
        f = feeds(sessions[0], a.size)

        def run():
            ts = [threading.Thread(target=s.run, args=(None, f)) for s in sessions]
            for t in ts:
                t.start()
            for t in ts:
                t.join()

        times = timed(run, a.reps)
        median = times[len(times) // 2]
        desc = (
            f"1 image, {intra} intra-op thread(s)"
            if name == "intra"
            else f"{images} images in parallel, 1 thread each"
        )
        print(json.dumps({
            "engine": "onnxruntime", "model": a.model, "width": width, "size": a.size,
            "threads": a.threads, "config": desc, "reps": a.reps,
            "min_s": round(times[0], 5), "median_s": round(median, 5),
            "mpix_per_s": round(images * a.size * a.size / median / 1e6, 4),
        }))


if __name__ == "__main__":
    main()
