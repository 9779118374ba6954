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


def claims(logs):
    """Sentences on the paper's training claims, from the validation curves."""
    out = []
    t2, t1 = logs.get("temc2-w0.125"), logs.get("temc1-w0.125")
    if t2 and t1:
        target = t1[-1][1]
        reach = next((t for t, v in t2 if v <= target), None)
        if reach is None:
            out.append(f"TEMC-2 trains faster than TEMC-1: **does not hold here**. TEMC-2 ended at "
                       f"validation loss {t2[-1][1]:.4f}, TEMC-1 at {target:.4f}.")
        else:
            out.append(f"TEMC-2 trains faster than TEMC-1: {'**holds**' if reach < t1[-1][0] else '**does not hold**'}"
                       f" here. TEMC-2 reached TEMC-1's final validation loss ({target:.4f}, after "
                       f"{t1[-1][0] / 60:.0f} CPU minutes) after {reach / 60:.1f} CPU minutes.")
    d = logs.get("demc-w0.125")
    if t2 and d:
        better = t2[-1][1] < d[-1][1]
        out.append(f"TEMC-2 beats DEMC (validation loss at the end of the budget): "
                   f"{'**holds**' if better else '**does not hold**'} here: {t2[-1][1]:.4f} against "
                   f"{d[-1][1]:.4f}. The test-scene errors are in the tables above.")
    return out or ["(the runs needed for this comparison are missing)"]


def verdict(mean, spps, labels, rows):
    """Sentences on the shipped TEMC-2 models against the noisy input, the baselines and OIDN.
    Means over scenes are dominated by the scene with the largest error (a firefly), so the
    per-scene count and the median ratio come first."""
    out = []
    temc2 = [l for l in labels if l.startswith("TEMC-2")]
    base = [l for l in labels if not l.startswith("TEMC-2")]
    err = {(r["denoiser"], r["scene"], r["spp"]): r["RelMSE"] for r in rows}
    cases = sorted({(r["scene"], r["spp"]) for r in rows})
    for l in labels + ["OIDN high"]:
        wins = sum(err[(l, c, s)] < err[("noisy", c, s)] for c, s in cases)
        ratio = float(np.median([err[("noisy", c, s)] / max(err[(l, c, s)], 1e-30) for c, s in cases]))
        out.append(f"{l}: lower RelMSE than the noisy input in {wins} of {len(cases)} (scene, spp) "
                   f"cases; median noisy/denoised RelMSE ratio {ratio:.3g}.")
    for l in temc2:
        ratios = [mean("noisy", s, "RelMSE") / mean(l, s, "RelMSE") for s in spps]
        beats = [b for b in base if all(mean(l, s, "RelMSE") < mean(b, s, "RelMSE") for s in spps)]
        loses = [b for b in base if b not in beats]
        oidn = [mean(l, s, "RelMSE") / mean("OIDN high", s, "RelMSE") for s in spps]
        out.append(f"{l}, means over the scenes: the noisy input's mean RelMSE is {min(ratios):.3g}x to "
                   f"{max(ratios):.3g}x its mean RelMSE (over {', '.join(f'{s}' for s in spps)} spp); lower mean than "
                   f"{', '.join(beats) if beats else 'no baseline'} at every spp"
                   + (f", not always lower than {', '.join(loses)}" if loses else "")
                   + f"; its RelMSE is {min(oidn):.3g}x to {max(oidn):.3g}x OIDN high's.")
        per_case = [f"{b} in {sum(err[(l, c, s)] < err[(b, c, s)] for c, s in cases)}"
                    for b in base + ["OIDN high"]]
        out.append(f"{l}, case by case: lower RelMSE than " + ", ".join(per_case)
                   + f" of the {len(cases)} (scene, spp) cases.")
    return out


# Issue 15's targets against OIDN high: (spp, RelMSE ratio bound, Delta E ratio bound).
TARGETS = ((4, 1.0, 1.0), (16, 0.8, 0.7), (64, 1.0, 1.0))
MEAN_TOLERANCE = 0.01


def targets(denoisers, spps, values, geomean, mean) -> list:
    """The targets section: per temc model and spp, geometric-mean RelMSE and mean Delta E
    ITP as ratios to OIDN high's on the same images, against the bounds, and the worst
    scene's |mean / reference mean - 1| (the noisy input's beside it: the render's own)."""
    ours = [n for n in denoisers if n.startswith("TEMC") or n.startswith("AE") or n.startswith("DEMC")]
    md = ["## Targets (issue 15)", "",
          "Geometric-mean RelMSE and mean Delta E ITP over the test scenes as ratios to OIDN "
          "high's on the same images (bounds: 16 spp RelMSE <= 0.8x and Delta E <= 0.7x; 4 and "
          f"64 spp no worse, <= 1x), and the worst scene's mean error (bound {100 * MEAN_TOLERANCE:.0f} %; "
          "the noisy input's worst is the render's own noise in the mean).", "",
          "| model | spp | RelMSE / OIDN | bound | dE ITP / OIDN | bound | worst mean error | noisy's worst | OIDN's worst |",
          "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    worst = lambda n, s: max((abs(v - 1) for v in values(n, s, "mean/ref")), default=float("nan"))  # noqa: E731
    for n in ours:
        for spp, rb, db in TARGETS:
            if spp not in spps:
                continue
            r = geomean(n, spp, "RelMSE") / geomean("OIDN high", spp, "RelMSE")
            d = mean(n, spp, "dE-ITP") / mean("OIDN high", spp, "dE-ITP")
            mark = lambda v, b: f"**{v:.2f}x**" if v <= b else f"{v:.2f}x"  # noqa: E731
            md.append(f"| {n} | {spp} | {mark(r, rb)} | {rb:g}x | {mark(d, db)} | {db:g}x | "
                      f"{100 * worst(n, spp):.1f} % | {100 * worst('noisy', spp):.1f} % | "
                      f"{100 * worst('OIDN high', spp):.1f} % |")
    return md + ["", "Bold: the bound is met.", ""]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", required=True)
    ap.add_argument("--temc", required=True, help="the temc binary")
    ap.add_argument("--model", action="append", default=[], help="an ONNX model (repeatable)")
    ap.add_argument("--runs", help="training runs folder (log.csv per run) for the training curves")
    ap.add_argument("--out", required=True, help="the Markdown report")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--timing-size", default="1920x1080")
    ap.add_argument("--aux-model", help="the model whose aux modes are compared (default: the "
                    "first --model named temc2-balanced.onnx, else the first)")
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
    aux_model = a.aux_model or next((m for m in a.model if m.endswith("temc2-balanced.onnx")),
                                    a.model[0] if a.model else None)
    aux_label = model_label(a.temc, aux_model)[0] if aux_model else None
    aux_rows = []

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
            # The three input sets (colour; + albedo; + normal and depth) at 16 spp: one
            # temc model trained with aux dropout against OIDN's separate weights.
            if spp == 16 and aux_model:
                for mode in ("full", "albedo", "none"):
                    for name, run in ((aux_label, lambda: ev.temc_denoise(a.temc, aux_model, path, a.threads, mode)),
                                      ("OIDN high", lambda: ev.oidn_denoise(layers, "high", mode))):
                        img, secs = (outs[name] if mode == "full" else run())
                        aux_rows.append({"scene": rec["name"], "denoiser": name, "aux": mode,
                                         "denoise_s": secs, **ev.all_metrics(img, ref)})
        print(f"evaluated {rec['name']}", flush=True)

    with open(os.path.join(img_dir, "measurements.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)

    spps = sorted({r["spp"] for r in rows})
    metrics = list(ev.METRICS)

    def values(name, spp, key):
        return [r[key] for r in rows if r["denoiser"] == name and r["spp"] == spp]

    def mean(name, spp, key):
        v = values(name, spp, key)
        return float(np.mean(v)) if v else float("nan")

    def geomean(name, spp, key):
        """The plot's and the raw-spp equivalence's average: one scene with a huge error
        (named-firefly's noisy input) would decide an arithmetic mean alone."""
        v = np.maximum(values(name, spp, key), 1e-12)
        return float(np.exp(np.mean(np.log(v)))) if v.size else float("nan")

    # Error against time: raw rendering at rising spp, and each denoiser after each spp.
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for name in denoisers:
        xs = [mean(name, s, "render_s") + mean(name, s, "denoise_s") for s in spps]
        ys = [geomean(name, s, "RelMSE") for s in spps]
        ax.plot(xs, ys, "o-" if name != "noisy" else "k--", label=name if name != "noisy" else "raw rendering")
        for x, y, s in zip(xs, ys, spps):
            if name == "noisy":
                ax.annotate(f"{s} spp", (x, y), fontsize=7)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("seconds per test image (render + denoise, 2 threads)")
    ax.set_ylabel("RelMSE (geometric mean over test scenes)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, which="both")
    fig.tight_layout()
    fig.savefig(os.path.join(img_dir, "error-vs-time.png"), dpi=110)
    plt.close(fig)

    # How many spp of raw rendering equal 16 spp denoised (log-log interpolation of the raw
    # curve, extrapolated along its last segment past 256 spp).
    raw = [(s, geomean("noisy", s, "RelMSE"), mean("noisy", s, "render_s")) for s in spps]

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
    logs = {}
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
            logs[name] = [(float(r["train_seconds"]), float(r["val_loss"])) for r in rs]
        ax.set_xlabel("CPU minutes in training steps (1 thread)")
        ax.set_ylabel("validation loss (L1 + MS-SSIM mix)")
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
        fig.tight_layout()
        fig.savefig(os.path.join(img_dir, "training.png"), dpi=110)
        plt.close(fig)

    import platform
    cpu = next((l.split(":", 1)[1].strip() for l in open("/proc/cpuinfo") if l.startswith("model name")),
               platform.processor())
    md = ["# Accuracy against time", "",
          "Regenerate with `scripts/accuracy-report` (one command; every number below comes from that run).",
          f"Test scenes: {len(tests)} ({', '.join(r['name'] for r in tests)}), {manifest['options']['size']}² pixels, "
          f"reference {manifest['options']['ref_spp']} spp. Denoising on {a.threads} threads of this machine; "
          "OIDN 2.5 through pyoidn (HDR, albedo + normal) measured in the same run. "
          f"Machine: {cpu}, {os.cpu_count()} logical CPUs, {time.strftime('%Y-%m-%d')}. Denoise seconds "
          "are execution only (model loading excluded, for temc and OIDN alike); render seconds come "
          "from the data set's progressive renders (2 threads), scaled by spp.", ""]
    md += targets(denoisers, spps, values, geomean, mean)
    for s in spps:
        md += [f"## {s} spp", "", "| denoiser | " + " | ".join(metrics) + " | denoise s |",
               "|---|" + "---:|" * (len(metrics) + 1)]
        for n in denoisers:
            md.append(f"| {n} | " + " | ".join(f"{mean(n, s, k):.4g}" for k in metrics)
                      + f" | {mean(n, s, 'denoise_s'):.3f} |")
        md.append("")
    md += ["## Error against time", "", "![error against time](img/accuracy/error-vs-time.png)", "",
           "RelMSE here is the geometric mean over the test scenes (the tables above give arithmetic "
           "means, which named-firefly's noisy input dominates).", "",
           "| denoiser at 16 spp | RelMSE (geo. mean) | raw spp with the same RelMSE | raw render seconds | 16 spp + denoise seconds |",
           "|---|---:|---:|---:|---:|"]
    if 16 in spps:
        for n in denoisers[1:]:
            e = geomean(n, 16, "RelMSE")
            spp, secs = equivalent(e)
            md.append(f"| {n} | {e:.4g} | {spp:.0f} | {secs:.1f} | "
                      f"{mean(n, 16, 'render_s') + mean(n, 16, 'denoise_s'):.1f} |")
    md += ["", f"## Denoising time at {a.timing_size}", "",
           "| denoiser | threads | median seconds |", "|---|---:|---:|"]
    md += [f"| {n} | {t} | {s:.3f} |" for n, t, s in timing]
    if aux_rows:
        md += ["", "## Inputs: colour, colour + albedo, colour + albedo + normal (16 spp)", "",
               f"{aux_label} is one model trained with random aux dropout (20 % colour only, some "
               "albedo only); OIDN ships separate weights per input set. Means over the test scenes.", "",
               "| denoiser | aux | " + " | ".join(metrics) + " |", "|---|---|" + "---:|" * len(metrics)]
        for name in (aux_label, "OIDN high"):
            for mode in ("full", "albedo", "none"):
                sel = [r for r in aux_rows if r["denoiser"] == name and r["aux"] == mode]
                md.append(f"| {name} | {mode} | " + " | ".join(
                    f"{np.mean([r[k] for r in sel]):.4g}" for k in metrics) + " |")
        with open(os.path.join(img_dir, "aux-modes.csv"), "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(aux_rows[0]))
            w.writeheader()
            w.writerows(aux_rows)
    if strip_files:
        md += ["", "## Hard cases at 16 spp", "", "Left to right: " + ", ".join(strip_names) + ".", ""]
        md += [f"**{s}**\n\n![{s}](img/accuracy/{fn})\n" for s, fn in strip_files]
    if curves:
        md += ["", "## Training", "", "![training curves](img/accuracy/training.png)", "",
               "| run | steps | training minutes | final validation loss |", "|---|---:|---:|---:|"]
        md += [f"| {n} | {r['step']} | {float(r['train_seconds']) / 60:.0f} | {float(r['val_loss']):.4f} |"
               for n, r in curves]
        md += ["", "The paper's claims, checked on these runs (same width 0.125, same budget):", ""]
        md += [f"- {line}" for line in claims(logs)]
    at = md.index(f"## {spps[0]} spp")
    block = ["## Verdict", ""] + [f"- {line}" for line in verdict(mean, spps, [m[0] for m in models], rows)] + [""]
    if 16 in spps:
        scenes = [r["name"] for r in tests]

        def err(n, c):
            return next(r["RelMSE"] for r in rows if r["denoiser"] == n and r["scene"] == c and r["spp"] == 16)

        block += ["## RelMSE per scene at 16 spp", "",
                  "| denoiser | " + " | ".join(scenes) + " |", "|---|" + "---:|" * len(scenes)]
        block += [f"| {n} | " + " | ".join(f"{err(n, c):.3g}" for c in scenes) + " |" for n in denoisers] + [""]
    scenes = [r["name"] for r in tests]

    def ratio(n, c, s):
        return next((r["mean/ref"] for r in rows if r["denoiser"] == n and r["scene"] == c
                     and r["spp"] == s), float("nan"))

    block += ["## Mean / reference mean per scene", "",
              "Energy: a denoiser keeps the image's mean (1.000); the noisy input's own ratio is the "
              "render's noise in the mean.", "",
              "| denoiser | spp | " + " | ".join(scenes) + " |", "|---|---:|" + "---:|" * len(scenes)]
    block += [f"| {n} | {s} | " + " | ".join(f"{ratio(n, c, s):.3f}" for c in scenes) + " |"
              for n in denoisers for s in spps] + [""]
    md[at:at] = block
    with open(a.out, "w") as f:
        f.write("\n".join(md) + "\n")
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
