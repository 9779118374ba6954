"""The accuracy-against-time report: every temc model, the raw renders and OIDN 2.5 on
the data set's test scenes, measured in one run.

    python -m temc_train.report --data ../data/spectral-v1 --temc ../target/release/temc \\
        --model ../onnx/temc2-balanced.onnx --model ../onnx/baselines/demc.onnx ... \\
        --runs runs --out ../docs/accuracy-vs-time.md

Writes the Markdown report, its plots and image strips (PNG, beside it under
img/accuracy/), and a CSV of every measurement. scripts/accuracy-report wraps it.
"""

import argparse
import csv
import glob
import json
import os
import subprocess
import time

import numpy as np

from . import evaluate as ev

HARD = ("named-cornell-spiky", "named-prism", "named-firefly", "named-dark-room", "named-laser")


def model_label(temc, path):
    r = subprocess.run([temc, "info", path, "--json"], capture_output=True, text=True, check=True)
    meta = json.loads(r.stdout)
    arch = meta.get("temc.architecture", "?").upper().replace("TEMC", "TEMC-")
    return f"{arch} w{float(meta.get('temc.width', 0)):g}", meta


def tonemap(rgb):
    x = np.clip(rgb, 0, None)
    x = x / (1 + x)
    x = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return (np.clip(x, 0, 1) * 255 + 0.5).astype(np.uint8)


def exposed(rgb, ref):
    return rgb * ev.auto_input_scale(ref) / 0.18 * 0.5


def oidn_timing(size, threads, quality, repeat=2):
    import pyoidn

    w, h = size
    rng = np.random.default_rng(0)
    c = rng.random((h, w, 3), np.float32)
    a = np.full((h, w, 3), 0.5, np.float32)
    n = np.zeros((h, w, 3), np.float32)
    n[..., 2] = 1
    out = np.zeros_like(c)
    dev = pyoidn.Device()
    dev.set_int("numThreads", threads)
    dev.commit()
    f = pyoidn.Filter(dev)
    f.set_image(pyoidn.OIDN_IMAGE_COLOR, c, pyoidn.OIDN_FORMAT_FLOAT3, w, h)
    f.set_image(pyoidn.OIDN_IMAGE_ALBEDO, a, pyoidn.OIDN_FORMAT_FLOAT3, w, h)
    f.set_image(pyoidn.OIDN_IMAGE_NORMAL, n, pyoidn.OIDN_FORMAT_FLOAT3, w, h)
    f.set_image(pyoidn.OIDN_IMAGE_OUTPUT, out, pyoidn.OIDN_FORMAT_FLOAT3, w, h)
    f.set_bool("hdr", True)
    f.set_quality({"high": pyoidn.OIDN_QUALITY_HIGH, "fast": pyoidn.OIDN_QUALITY_FAST}[quality])
    f.commit()
    f.execute()
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        f.execute()
        times.append(time.perf_counter() - t)
    f.release()
    dev.release()
    return float(np.median(times))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", required=True)
    ap.add_argument("--temc", required=True, help="the temc binary")
    ap.add_argument("--model", action="append", default=[], help="an ONNX model (repeatable)")
    ap.add_argument("--runs", help="training runs folder (log.csv per run) for the training curves")
    ap.add_argument("--out", required=True, help="the Markdown report")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--timing-size", default="1920x1080")
    a = ap.parse_args(argv)

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from PIL import Image

    out_dir = os.path.dirname(os.path.abspath(a.out))
    img_dir = os.path.join(out_dir, "img", "accuracy")
    os.makedirs(img_dir, exist_ok=True)
    with open(os.path.join(a.data, "manifest.json")) as f:
        manifest = json.load(f)
    tests = [r for r in manifest["scenes"] if r["split"] == "test"]
    if not tests:
        raise SystemExit("no finished test scenes in the data set yet")
    models = [(model_label(a.temc, m)[0], m) for m in a.model]
    denoisers = ["noisy"] + [m[0] for m in models] + ["OIDN high", "OIDN fast"]

    rows = []
    strips = {}
    for rec in tests:
        d = os.path.join(a.data, rec["dir"])
        ref = ev.read_exr(os.path.join(d, rec["reference"]))["color"]
        max_spp = max(s for s, _ in rec["noisy"])
        for spp, fname in rec["noisy"]:
            path = os.path.join(d, fname)
            layers = ev.read_exr(path)
            render_s = rec["seconds_noisy"] * spp / max_spp
            outs = {"noisy": (layers["color"], 0.0)}
            for label, m in models:
                outs[label] = ev.temc_denoise(a.temc, m, path, a.threads)
            outs["OIDN high"] = ev.oidn_denoise(layers, "high")
            outs["OIDN fast"] = ev.oidn_denoise(layers, "fast")
            for name, (img, secs) in outs.items():
                rows.append({"scene": rec["name"], "spp": spp, "denoiser": name,
                             "render_s": render_s, "denoise_s": secs, **ev.all_metrics(img, ref)})
            if rec["name"] in HARD and spp == 16:
                strips[rec["name"]] = (outs, ref)
        print(f"evaluated {rec['name']}", flush=True)

    with open(os.path.join(img_dir, "measurements.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)

    spps = sorted({r["spp"] for r in rows})
    metrics = list(ev.METRICS)

    def mean(name, spp, key):
        v = [r[key] for r in rows if r["denoiser"] == name and r["spp"] == spp]
        return float(np.mean(v)) if v else float("nan")

    # Error against time: raw rendering at rising spp, and each denoiser after each spp.
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for name in denoisers:
        xs = [mean(name, s, "render_s") + mean(name, s, "denoise_s") for s in spps]
        ys = [mean(name, s, "RelMSE") for s in spps]
        ax.plot(xs, ys, "o-" if name != "noisy" else "k--", label=name if name != "noisy" else "raw rendering")
        for x, y, s in zip(xs, ys, spps):
            if name == "noisy":
                ax.annotate(f"{s} spp", (x, y), fontsize=7)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("seconds per test image (render + denoise, 2 threads)")
    ax.set_ylabel("RelMSE (mean over test scenes)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, which="both")
    fig.tight_layout()
    fig.savefig(os.path.join(img_dir, "error-vs-time.png"), dpi=110)
    plt.close(fig)

    # How many spp of raw rendering equal 16 spp denoised (log-log interpolation of the raw
    # curve, extrapolated along its last segment past 256 spp).
    raw = [(s, mean("noisy", s, "RelMSE"), mean("noisy", s, "render_s")) for s in spps]

    def equivalent(err):
        ls = np.log([r[0] for r in raw])
        le = np.log([r[1] for r in raw])
        if err >= raw[0][1]:
            return float(raw[0][0]), raw[0][2]
        k = len(raw) - 2
        for i in range(len(raw) - 1):
            if raw[i + 1][1] <= err:
                k = i
                break
        slope = (ls[k + 1] - ls[k]) / (le[k + 1] - le[k])
        spp = float(np.exp(ls[k] + slope * (np.log(err) - le[k])))
        return spp, raw[k][2] * spp / raw[k][0]

    # Timing at the timing size per model and thread count, OIDN in the same run.
    tw, th = (int(v) for v in a.timing_size.split("x"))
    timing = []
    for threads in (1, a.threads):
        for label, m in models:
            r = subprocess.run([a.temc, "bench", "--model", m, "--size", a.timing_size, "--threads",
                                str(threads), "--repeat", "2", "--json"],
                               capture_output=True, text=True, check=True)
            timing.append((label, threads, json.loads(r.stdout)["median_seconds"]))
        for q in ("high", "fast"):
            timing.append((f"OIDN {q}", threads, oidn_timing((tw, th), threads, q)))

    # Image strips of the hard cases at 16 spp.
    strip_names = ["noisy", "OIDN high"] + [m[0] for m in models] + ["reference"]
    strip_files = []
    for scene, (outs, ref) in strips.items():
        h, w = ref.shape[:2]
        c = min(128, h, w)
        y0, x0 = (h - c) // 2, (w - c) // 2
        tiles = []
        for n in strip_names:
            img = ref if n == "reference" else outs[n][0]
            tiles.append(tonemap(exposed(img, ref))[y0:y0 + c, x0:x0 + c])
        fn = f"crops-{scene}.png"
        Image.fromarray(np.concatenate(tiles, 1)).resize((c * 2 * len(tiles), c * 2), Image.NEAREST).save(
            os.path.join(img_dir, fn))
        strip_files.append((scene, fn))

    # Training curves.
    curves = []
    if a.runs:
        fig, ax = plt.subplots(figsize=(7, 4))
        for log in sorted(glob.glob(os.path.join(a.runs, "*", "log.csv"))):
            with open(log) as f:
                rs = [r for r in csv.DictReader(f) if r["val_loss"]]
            if len(rs) < 2:
                continue
            name = os.path.basename(os.path.dirname(log))
            ax.plot([float(r["train_seconds"]) / 60 for r in rs], [float(r["val_loss"]) for r in rs], label=name)
            curves.append((name, rs[-1]))
        ax.set_xlabel("training minutes (2 CPU threads)")
        ax.set_ylabel("validation loss (L1 + MS-SSIM mix)")
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
        fig.tight_layout()
        fig.savefig(os.path.join(img_dir, "training.png"), dpi=110)
        plt.close(fig)

    md = ["# Accuracy against time", "",
          "Regenerate with `scripts/accuracy-report` (one command; every number below comes from that run).",
          f"Test scenes: {len(tests)} ({', '.join(r['name'] for r in tests)}), {manifest['options']['size']}² pixels, "
          f"reference {manifest['options']['ref_spp']} spp. Denoising on {a.threads} threads of this machine; "
          "OIDN 2.5 through pyoidn (HDR, albedo + normal) measured in the same run.", ""]
    for s in spps:
        md += [f"## {s} spp", "", "| denoiser | " + " | ".join(metrics) + " | denoise s |",
               "|---|" + "---:|" * (len(metrics) + 1)]
        for n in denoisers:
            md.append(f"| {n} | " + " | ".join(f"{mean(n, s, k):.4g}" for k in metrics)
                      + f" | {mean(n, s, 'denoise_s'):.3f} |")
        md.append("")
    md += ["## Error against time", "", "![error against time](img/accuracy/error-vs-time.png)", "",
           "| denoiser at 16 spp | RelMSE | raw spp with the same RelMSE | raw render seconds | 16 spp + denoise seconds |",
           "|---|---:|---:|---:|---:|"]
    if 16 in spps:
        for n in denoisers[1:]:
            e = mean(n, 16, "RelMSE")
            spp, secs = equivalent(e)
            md.append(f"| {n} | {e:.4g} | {spp:.0f} | {secs:.1f} | "
                      f"{mean(n, 16, 'render_s') + mean(n, 16, 'denoise_s'):.1f} |")
    md += ["", f"## Denoising time at {a.timing_size}", "",
           "| denoiser | threads | median seconds |", "|---|---:|---:|"]
    md += [f"| {n} | {t} | {s:.3f} |" for n, t, s in timing]
    if strip_files:
        md += ["", "## Hard cases at 16 spp", "", "Left to right: " + ", ".join(strip_names) + ".", ""]
        md += [f"**{s}**\n\n![{s}](img/accuracy/{fn})\n" for s, fn in strip_files]
    if curves:
        md += ["", "## Training", "", "![training curves](img/accuracy/training.png)", "",
               "| run | steps | training minutes | final validation loss |", "|---|---:|---:|---:|"]
        md += [f"| {n} | {r['step']} | {float(r['train_seconds']) / 60:.0f} | {float(r['val_loss']):.4f} |"
               for n, r in curves]
    with open(a.out, "w") as f:
        f.write("\n".join(md) + "\n")
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
