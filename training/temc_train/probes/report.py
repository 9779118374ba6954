"""The accuracy-against-time report: every temc model, the raw renders and OIDN 2.5 on
the data set's test scenes, measured in one run.

    python -m temc_train.probes.report --data ../data/spectral-v1 --temc ../target/release/temc \\
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

from .. import evaluate as ev
from ..models import ARCH_NAMES, label

HARD = ("named-cornell-spiky", "named-prism", "named-firefly", "named-dark-room", "named-laser")
# The default page: the accuracy report of the project's own data set.
PAGE = {"title": "Accuracy against time", "command": "scripts/accuracy-report", "img": "img/accuracy",
        "about": "every hand-written and held-out-family test scene, and the generator's first "
                 "test seeds by index, `--generated`",
        "renders": "the data set's progressive renders (2 threads)"}


def model_label(temc, path):
    """(name, metadata) of an ONNX model; the name is models.label's, as on its model card."""
    r = subprocess.run([temc, "info", path, "--json"], capture_output=True, text=True, check=True)
    meta = json.loads(r.stdout)
    return label(meta["temc.architecture"], meta["temc.width"], meta.get("temc.levels", "1"),
                 meta.get("temc.passes", "1")), meta


def distinct_labels(names, paths):
    """The models' labels, each shared one followed by its file's name: the report keys its
    rows by label, so two candidates of one shape would otherwise print one's numbers twice."""
    return [f"{n} ({os.path.splitext(os.path.basename(p))[0]})" if names.count(n) > 1 else n
            for n, p in zip(names, paths)]


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
    temc2 = [l for l in labels if l.startswith(ARCH_NAMES["temc2"])]
    base = [l for l in labels if not l.startswith(ARCH_NAMES["temc2"])]
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


# Issue 36's targets against OIDN high: (spp, RelMSE ratio bound, Delta E ratio bound).
TARGETS = ((4, 1.0, 0.8), (16, 1.0, 0.8), (64, 1.0, 0.8))
MEAN_TOLERANCE = 0.01


def vs_oidn(values, geomean, mean, n, spp):
    """Model `n` at `spp` against OIDN high on the same images: (geometric-mean RelMSE ratio,
    mean Delta E ITP ratio, worst |mean / reference mean - 1|)."""
    r = geomean(n, spp, "RelMSE") / geomean("OIDN high", spp, "RelMSE")
    d = mean(n, spp, "dE-ITP") / mean("OIDN high", spp, "dE-ITP")
    return r, d, worst_mean_error(values, n, spp)


def worst_mean_error(values, n, spp):
    return max((abs(v - 1) for v in values(n, spp, "mean/ref")), default=float("nan"))


def targets(denoisers, spps, values, geomean, mean) -> list:
    """The targets section: per temc model and spp, geometric-mean RelMSE and mean Delta E
    ITP as ratios to OIDN high's on the same images, against the bounds, and the worst
    scene's |mean / reference mean - 1| (the noisy input's beside it: the render's own);
    then each model's ratios over the bounds, how far it misses them."""
    ours = [n for n in denoisers if n.startswith(tuple(ARCH_NAMES.values()))]
    md = ["## Targets (issue 36)", "",
          "Geometric-mean RelMSE and mean Delta E ITP over the test scenes as ratios to OIDN "
          "high's on the same images (bounds: RelMSE <= 1x and Delta E <= 0.8x at 4, 16 and 64 "
          f"spp), and the worst scene's mean error (bound {100 * MEAN_TOLERANCE:.0f} %; "
          "the noisy input's worst is the render's own noise in the mean).", "",
          "| model | spp | RelMSE / OIDN | bound | dE ITP / OIDN | bound | worst mean error | noisy's worst | OIDN's worst |",
          "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    worst = lambda n, s: worst_mean_error(values, n, s)  # noqa: E731
    missed = []
    for n in ours:
        by = {"RelMSE": [], "dE ITP": []}
        for spp, rb, db in TARGETS:
            if spp not in spps:
                continue
            r, d, w = vs_oidn(values, geomean, mean, n, spp)
            mark = lambda v, b: f"**{v:.2f}x**" if v <= b else f"{v:.2f}x"  # noqa: E731
            md.append(f"| {n} | {spp} | {mark(r, rb)} | {rb:g}x | {mark(d, db)} | {db:g}x | "
                      f"{100 * w:.1f} % | {100 * worst('noisy', spp):.1f} % | "
                      f"{100 * worst('OIDN high', spp):.1f} % |")
            by["RelMSE"].append((spp, r / rb))
            by["dE ITP"].append((spp, d / db))
        missed += [f"- {n}: " + "; ".join(
            f"{k} {' / '.join(f'{v:.2f}x' for _, v in got)} its bound at "
            f"{' / '.join(str(s) for s, _ in got)} spp" for k, got in by.items() if got) + "."]
    return md + ["", "Bold: the bound is met. By how much each model misses or meets its bounds "
                 "(its ratio over the bound; above 1x: missed):", ""] + missed + [
        ""] + delta_e_parts(ours, spps, mean) + [
        "What was tried, each step measured, and the lever each result points to: "
        "docs/reconstruction.md.", ""]


def delta_e_parts(ours, spps, mean) -> list:
    """Delta E ITP's ratio to OIDN high's beside its intensity part's and its chroma part's
    (evaluate.delta_e_intensity, delta_e_chroma): which of the two a model misses on."""
    if not np.isfinite(mean("OIDN high", max(spps, default=0), "dE-I")):
        return []  # measured before the parts were
    md = ["Delta E ITP split into its intensity part (mean 720 |dI|: light and dark) and its "
          "chroma part (mean 720 sqrt((dCt / 2)^2 + dCp^2): colour), each as a ratio to OIDN "
          "high's:", "", "| model | spp | dE ITP / OIDN | intensity / OIDN | chroma / OIDN |",
          "|---|---:|---:|---:|---:|"]
    for n in ours:
        for spp in (s for s, _, _ in TARGETS if s in spps):
            md.append(f"| {n} | {spp} | " + " | ".join(
                f"{mean(n, spp, k) / mean('OIDN high', spp, k):.2f}x"
                for k in ("dE-ITP", "dE-I", "dE-CtCp")) + " |")
    return md + [""]


# The three kinds of test scene, by name prefix: hand-written (another author's composition,
# lights and materials), whole families the generator never trains on (layouts and lighting
# of render/src/description/held_out.rs), and the generator's own on held-out seeds.
FAMILIES = (("hand-written scenes (named-*: not made by the generator)", "named-"),
            ("held-out families (holdout-*: window-lit rooms, lamp-lined corridors)", "holdout-"),
            ("generated scenes (held-out seeds of the training generator)", "scene-"))


def family_section(m, denoisers, spps) -> list:
    """The targets' ratios to OIDN high again, per kind of test scene: a model that has
    learnt its generator rather than denoising wins on the last and not on the first two."""
    if not any(r["scene"].startswith(prefix) for r in m.rows for _, prefix in FAMILIES):
        return []  # another renderer's family: no scene is of these kinds
    md = ["## Targets per kind of test scene", "",
          "The same ratios to OIDN high on each kind of test scene alone: scenes of other "
          "families (hand-written, and the generator's held-out families: no training scene "
          "has their layout or lighting) and held-out seeds of the family trained on.", "",
          "| model | scenes | n | spp | RelMSE / OIDN | dE ITP / OIDN | worst mean error |",
          "|---|---|---:|---:|---:|---:|---:|"]
    for label, n_scenes, sub, n, spp in per_kind(m, denoisers, spps, FAMILIES):
        r, d, worst = vs_oidn(sub.values, sub.geomean, sub.mean, n, spp)
        md.append(f"| {n} | {label} | {n_scenes} | {spp} | {r:.2f}x | {d:.2f}x | {100 * worst:.1f} % |")
    return md + [""]


def per_kind(m, denoisers, spps, kinds, keep=lambda row: True):
    """The rows of a per-kind table: (kind's label, its scene count, its Means, temc model,
    target spp) for each kind of test scene (label, name prefix) that has scenes among the
    rows `keep` accepts."""
    ours = [n for n in denoisers if n.startswith(tuple(ARCH_NAMES.values()))]
    for label, prefix in kinds:
        sub = Means([r for r in m.rows if r["scene"].startswith(prefix) and keep(r)])
        n_scenes = len({r["scene"] for r in sub.rows})
        for n in ours if n_scenes else ():
            for spp in (s for s, _, _ in TARGETS if s in spps):
                yield label, n_scenes, sub, n, spp


def reference_noise_section(m, denoisers, spps) -> list:
    """The targets' RelMSE ratios once more with each reference's own noise subtracted
    (RelMSE-net), for all test scenes and per kind: 512-spp references are noisy enough to
    hide part of a denoiser's error at 64 spp (issue 36, item 4). Empty where the data set
    keeps no reference prefixes."""
    if not any("RelMSE-net" in r for r in m.rows):
        return []
    md = ["## RelMSE with each reference's own noise subtracted", "",
          "A reference carries noise of its own, and RelMSE against it counts that "
          "noise as the denoiser's error: E[(x - ref)^2] = (x - truth)^2 + var(ref) for a "
          "reference rendered with its own seed. var(ref) per pixel comes from a render of the "
          "reference's first samples, which the data set keeps (evaluate.reference_variance); "
          "'noise removed' is the geometric-mean RelMSE ratio to OIDN high after subtracting "
          "it (evaluate.relmse_net). 'Reference / OIDN' is the reference's own RelMSE over "
          "OIDN high's: near 1, the reference is about as far from the truth as OIDN is. A "
          "scene's net value at or below zero (the denoiser closer to the truth than the "
          "reference; counted in the last column, the model's / OIDN's) enters the geometric "
          "mean as 1e-12.", "",
          "| model | scenes | n | spp | RelMSE / OIDN | noise removed | reference / OIDN | net <= 0 |",
          "|---|---|---:|---:|---:|---:|---:|---:|"]
    kinds = (("all test scenes", ""),) + FAMILIES
    for label, n_scenes, sub, n, spp in per_kind(m, denoisers, spps, kinds,
                                                 lambda row: "RelMSE-net" in row):
        oidn = sub.geomean("OIDN high", spp, "RelMSE")
        raw = sub.geomean(n, spp, "RelMSE") / oidn
        net = sub.geomean(n, spp, "RelMSE-net") / sub.geomean("OIDN high", spp, "RelMSE-net")
        floor = sub.geomean(n, spp, "ref RelMSE") / oidn
        low = "/".join(str(sum(v <= 0 for v in sub.values(name, spp, "RelMSE-net")))
                       for name in (n, "OIDN high"))
        md.append(f"| {n} | {label} | {n_scenes} | {spp} | {raw:.2f}x | {net:.2f}x | "
                  f"{floor:.2f} | {low} |")
    return md + [""]


class Means:
    """The report's averages over the test scenes of one denoiser at one spp."""

    def __init__(self, rows):
        self.rows = rows

    def values(self, name, spp, key):
        """Rows measured before a metric joined (older CSVs) have no value for it."""
        return [r[key] for r in self.rows if r["denoiser"] == name and r["spp"] == spp and key in r]

    def mean(self, name, spp, key):
        v = self.values(name, spp, key)
        return float(np.mean(v)) if v else float("nan")

    def geomean(self, name, spp, key):
        """The plot's and the raw-spp equivalence's average: one scene with a huge error
        (named-firefly's noisy input) would decide an arithmetic mean alone."""
        v = np.maximum(self.values(name, spp, key), 1e-12)
        return float(np.exp(np.mean(np.log(v)))) if v.size else float("nan")

    def at(self, name, scene, spp, key):
        """One scene's value, NaN when it was not measured."""
        return next((r[key] for r in self.rows if r["denoiser"] == name and r["scene"] == scene
                     and r["spp"] == spp), float("nan"))


def temc_denoiser(temc, model, threads):
    """A temc model as the report runs it: (EXR path, layers, aux mode) -> (image, seconds)."""
    return lambda path, layers, aux="full": ev.temc_denoise(temc, model, path, threads, aux)


def temc_bench(temc, model, size):
    """A temc model's median seconds at `size` ("WxH") on `threads` threads."""
    def bench(threads):
        r = subprocess.run([temc, "bench", "--model", model, "--size", size, "--threads",
                            str(threads), "--repeat", "2", "--json"],
                           capture_output=True, text=True, check=True)
        return json.loads(r.stdout)["median_seconds"]
    return bench


def oidn_denoiser(quality):
    return lambda path, layers, aux="full": ev.oidn_denoise(layers, quality, aux)


# OIDN as the report compares it: name -> quality.
OIDN = {"OIDN high": "high", "OIDN fast": "fast"}


def measure_scene(rec, root, denoisers, aux):
    """Every denoiser on every noisy render of one test scene: (rows, aux rows, the 16-spp
    outputs and reference for the image strips or None). `denoisers` maps names to
    (path, layers, aux mode) -> (image, seconds); `aux` is (name, denoiser) of the temc
    model whose aux modes are compared, or None."""
    d = os.path.join(root, rec["dir"])
    ref = ev.read_exr(os.path.join(d, rec["reference"]))["color"]
    ref_var = reference_noise(d, rec, ref)
    max_spp = max(s for s, _ in rec["noisy"])
    rows, aux_rows, strip = [], [], None
    for spp, fname in rec["noisy"]:
        path = os.path.join(d, fname)
        layers = ev.read_exr(path)
        render_s = rec["seconds_noisy"] * spp / max_spp
        outs = {"noisy": (layers["color"], 0.0)}
        outs.update((name, run(path, layers)) for name, run in denoisers.items())
        for name, (img, secs) in outs.items():
            rows.append({"scene": rec["name"], "spp": spp, "denoiser": name,
                         "render_s": render_s, "denoise_s": secs, **ev.all_metrics(img, ref),
                         "border/ref": ev.border_ratio(img, ref),
                         "dark RelMSE": ev.dark_relmse(img, ref)})
            if ref_var is not None:
                rows[-1].update({"RelMSE-net": ev.relmse_net(img, ref, ref_var),
                                 "ref RelMSE": ev.reference_relmse(ref, ref_var)})
        if spp == 16:
            strip = (outs, ref)
            if aux:
                aux_rows += measure_aux_modes(rec["name"], path, layers, ref, outs, aux, denoisers)
    return rows, aux_rows, strip


def reference_noise(d, rec, ref):
    """The per-pixel variance of the scene's reference (evaluate.reference_variance) from
    the data set's reference prefix, or None where it keeps none (the Cycles family's
    8192-spp references have no prefix)."""
    prefixes = rec.get("reference_prefixes") or []
    if not prefixes or not rec.get("ref_spp"):
        return None
    k, fname = prefixes[0]
    prefix = ev.read_exr(os.path.join(d, fname))["color"]
    return ev.reference_variance(ref, prefix, rec["ref_spp"], k)


def measure_aux_modes(scene, path, layers, ref, outs, aux, denoisers):
    """The three input sets (colour; + albedo; + normal and depth) at 16 spp: one temc
    model trained with aux dropout against OIDN's separate weights."""
    rows = []
    for mode in ("full", "albedo", "none"):
        for name, run in (aux, ("OIDN high", denoisers["OIDN high"])):
            img, secs = outs[name] if mode == "full" and name in outs else run(path, layers, mode)
            rows.append({"scene": scene, "denoiser": name, "aux": mode, "denoise_s": secs,
                         **ev.all_metrics(img, ref)})
    return rows


def measure(root, tests, denoisers, aux, strip_scenes=HARD):
    """measure_scene over the test scenes: (rows, aux rows, strips of `strip_scenes`)."""
    rows, aux_rows, strips = [], [], {}
    for rec in tests:
        r, ar, strip = measure_scene(rec, root, denoisers, aux)
        rows += r
        aux_rows += ar
        if rec["name"] in strip_scenes and strip:
            strips[rec["name"]] = strip
        print(f"evaluated {rec['name']}", flush=True)
    return rows, aux_rows, strips


def timings(bench, threads, size, oidn_time):
    """(denoiser, threads, median seconds) at `size` on one thread and on `threads`; `bench`
    maps each temc model's name to threads -> seconds."""
    tw, th = (int(v) for v in size.split("x"))
    out = []
    for t in (1, threads):
        out += [(label, t, b(t)) for label, b in bench.items()]
        out += [(name, t, oidn_time((tw, th), t, q)) for name, q in OIDN.items()]
    return out


def write_csv(path, rows):
    with open(path, "w", newline="") as f:
        # Every key of every row: scenes with a reference prefix add RelMSE-net.
        keys = list(dict.fromkeys(k for r in rows for k in r))
        w = csv.DictWriter(f, fieldnames=keys, restval="")
        w.writeheader()
        w.writerows(rows)


def plot_error_vs_time(plt, denoisers, spps, m, path):
    """Error against time: raw rendering at rising spp, and each denoiser after each spp."""
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for name in denoisers:
        xs = [m.mean(name, s, "render_s") + m.mean(name, s, "denoise_s") for s in spps]
        ys = [m.geomean(name, s, "RelMSE") for s in spps]
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
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_strips(strips, names, img_dir):
    """Image strips of the hard cases at 16 spp (centre crops, tone-mapped, 2x); returns
    (scene, file name) per strip."""
    from PIL import Image

    files = []
    for scene, (outs, ref) in strips.items():
        h, w = ref.shape[:2]
        c = min(128, h, w)
        y0, x0 = (h - c) // 2, (w - c) // 2
        tiles = [tonemap(exposed(ref if n == "reference" else outs[n][0], ref))[y0:y0 + c, x0:x0 + c]
                 for n in names]
        fn = f"crops-{scene}.png"
        Image.fromarray(np.concatenate(tiles, 1)).resize((c * 2 * len(tiles), c * 2), Image.NEAREST).save(
            os.path.join(img_dir, fn))
        files.append((scene, fn))
    return files


def read_training_logs(runs):
    """Per run with two or more validations: (curves: (name, last row), logs: name ->
    [(train seconds, val loss)])."""
    curves, logs = [], {}
    for log in sorted(glob.glob(os.path.join(runs, "*", "log.csv"))):
        with open(log) as f:
            rs = [r for r in csv.DictReader(f) if r["val_loss"]]
        if len(rs) < 2:
            continue
        name = os.path.basename(os.path.dirname(log))
        curves.append((name, rs[-1]))
        logs[name] = [(float(r["train_seconds"]), float(r["val_loss"])) for r in rs]
    return curves, logs


def plot_training(plt, logs, path):
    fig, ax = plt.subplots(figsize=(7, 4))
    for name, pts in logs.items():
        ax.plot([t / 60 for t, _ in pts], [v for _, v in pts], label=name)
    ax.set_xlabel("CPU minutes in training steps (1 thread)")
    ax.set_ylabel("validation loss (L1 + MS-SSIM mix)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def machine():
    """This machine, for the report's header."""
    import platform

    cpu = next((l.split(":", 1)[1].strip() for l in open("/proc/cpuinfo") if l.startswith("model name")),
               platform.processor())
    return f"{cpu}, {os.cpu_count()} logical CPUs, {time.strftime('%Y-%m-%d')}"


def header(tests, manifest, threads, where, page=None):
    page = page or PAGE
    return [f"# {page['title']}", "",
            f"Regenerate with `{page['command']}` (one command; every number below comes from that run).",
            f"Test scenes: {len(tests)} ({', '.join(r['name'] for r in tests)}; {page['about']}), "
            f"{manifest['options']['size']}² pixels, "
            f"reference {manifest['options']['ref_spp']} spp. Denoising on {threads} threads of this machine; "
            "OIDN 2.5 through pyoidn (HDR, albedo + normal) measured in the same run. "
            f"Machine: {where}. Denoise seconds "
            "are execution only (model loading excluded, for temc and OIDN alike); render seconds come "
            f"from {page['renders']}, scaled by spp.", ""]


def verdict_section(m, spps, labels):
    return ["## Verdict", ""] + [f"- {line}" for line in verdict(m.mean, spps, labels, m.rows)] + [""]


def per_scene_section(m, denoisers, spps, scenes):
    """RelMSE per scene at 16 spp (when measured), and every scene's mean / reference mean."""
    md = []
    if 16 in spps:
        md += ["## RelMSE per scene at 16 spp", "",
               "| denoiser | " + " | ".join(scenes) + " |", "|---|" + "---:|" * len(scenes)]
        md += [f"| {n} | " + " | ".join(f"{m.at(n, c, 16, 'RelMSE'):.3g}" for c in scenes) + " |"
               for n in denoisers] + [""]
    md += ["## Mean / reference mean per scene", "",
           "Energy: a denoiser keeps the image's mean (1.000); the noisy input's own ratio is the "
           "render's noise in the mean.", "",
           "| denoiser | spp | " + " | ".join(scenes) + " |", "|---|---:|" + "---:|" * len(scenes)]
    md += [f"| {n} | {s} | " + " | ".join(f"{m.at(n, c, s, 'mean/ref'):.3f}" for c in scenes) + " |"
           for n in denoisers for s in spps] + [""]
    return md


def border_section(m, denoisers, spps):
    """The image frame's mean over the reference's (evaluate.border_ratio) per denoiser and
    spp: mean and extremes over the scenes. Measurements from before the column have none."""
    if not m.rows or "border/ref" not in m.rows[0]:
        return []
    md = ["## Border", "",
          f"Mean of the outer {ev.BORDER_PX}-px frame over the reference's there (1.000: no "
          "border artefact); mean over the scenes, and the lowest and highest scene.", "",
          "| denoiser | " + " | ".join(f"{s} spp" for s in spps) + " |",
          "|---|" + "---:|" * len(spps)]
    for n in denoisers:
        cells = []
        for s in spps:
            v = m.values(n, s, "border/ref")
            cells.append(f"{np.mean(v):.3f} ({min(v):.3f}-{max(v):.3f})" if v else "-")
        md.append(f"| {n} | " + " | ".join(cells) + " |")
    return md + [""]


def dark_section(m, denoisers, spps):
    """RelMSE over each reference's darkest pixels (evaluate.dark_relmse) per denoiser and
    spp, as the geometric mean over the scenes of its ratio to OIDN high's, with the worst
    scene. Measurements from before the column have none."""
    if not m.rows or "dark RelMSE" not in m.rows[0] or "OIDN high" not in denoisers:
        return []
    md = ["## Dark regions", "",
          f"RelMSE over the darkest {ev.DARK_SHARE:.0%} of each reference's pixels (by "
          "luminance), where blotches around sparse samples show, as a ratio to OIDN high's on "
          "the same pixels: geometric mean over the scenes, and the worst scene.", "",
          "| denoiser | " + " | ".join(f"{s} spp" for s in spps) + " |",
          "|---|" + "---:|" * len(spps)]
    key, scenes = "dark RelMSE", list(dict.fromkeys(r["scene"] for r in m.rows))
    for n in (d for d in denoisers if d != "OIDN high"):
        cells = []
        for s in spps:
            # The worst scene's own ratio; the mean as the targets' RelMSE / OIDN is taken.
            ratio = {c: m.at(n, c, s, key) / max(m.at("OIDN high", c, s, key), 1e-12) for c in scenes}
            ratio = {c: v for c, v in ratio.items() if np.isfinite(v)}
            worst = max(ratio, key=ratio.get, default=None)
            geo = m.geomean(n, s, key) / m.geomean("OIDN high", s, key)
            cells.append(f"{geo:.2f}x ({worst} {ratio[worst]:.2f}x)" if worst else "-")
        md.append(f"| {n} | " + " | ".join(cells) + " |")
    return md + [""]


def spp_tables(m, denoisers, spps):
    metrics = list(ev.METRICS)
    md = []
    for s in spps:
        md += [f"## {s} spp", "", "| denoiser | " + " | ".join(metrics) + " | denoise s |",
               "|---|" + "---:|" * (len(metrics) + 1)]
        for n in denoisers:
            md.append(f"| {n} | " + " | ".join(f"{m.mean(n, s, k):.4g}" for k in metrics)
                      + f" | {m.mean(n, s, 'denoise_s'):.3f} |")
        md.append("")
    return md


def raw_equivalent(raw, err):
    """(spp, render seconds) of raw rendering with RelMSE `err`: log-log interpolation of
    the raw curve `raw` [(spp, geomean RelMSE, render seconds)], extrapolated along its
    last segment past the highest spp."""
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


def error_vs_time_section(m, denoisers, spps, img="img/accuracy"):
    """How many spp of raw rendering equal 16 spp denoised."""
    md = ["## Error against time", "", f"![error against time]({img}/error-vs-time.png)", "",
          "RelMSE here is the geometric mean over the test scenes (the tables above give arithmetic "
          "means, which named-firefly's noisy input dominates).", "",
          "| denoiser at 16 spp | RelMSE (geo. mean) | raw spp with the same RelMSE | raw render seconds | 16 spp + denoise seconds |",
          "|---|---:|---:|---:|---:|"]
    if 16 in spps:
        raw = [(s, m.geomean("noisy", s, "RelMSE"), m.mean("noisy", s, "render_s")) for s in spps]
        for n in denoisers[1:]:
            e = m.geomean(n, 16, "RelMSE")
            spp, secs = raw_equivalent(raw, e)
            md.append(f"| {n} | {e:.4g} | {spp:.0f} | {secs:.1f} | "
                      f"{m.mean(n, 16, 'render_s') + m.mean(n, 16, 'denoise_s'):.1f} |")
    return md


def timing_section(size, timing):
    if not timing:
        return []
    return (["", f"## Denoising time at {size}", "", "| denoiser | threads | median seconds |", "|---|---:|---:|"]
            + [f"| {n} | {t} | {s:.3f} |" for n, t, s in timing])


def aux_section(aux_label, aux_rows):
    if not aux_rows:
        return []
    metrics = list(ev.METRICS)
    md = ["", "## Inputs: colour, colour + albedo, colour + albedo + normal (16 spp)", "",
          f"{aux_label} is one model trained with random aux dropout (20 % colour only, some "
          "albedo only); OIDN ships separate weights per input set. Means over the test scenes.", "",
          "| denoiser | aux | " + " | ".join(metrics) + " |", "|---|---|" + "---:|" * len(metrics)]
    for name in (aux_label, "OIDN high"):
        for mode in ("full", "albedo", "none"):
            sel = [r for r in aux_rows if r["denoiser"] == name and r["aux"] == mode]
            md.append(f"| {name} | {mode} | " + " | ".join(
                f"{np.mean([r[k] for r in sel]):.4g}" for k in metrics) + " |")
    return md


def strips_section(names, files, img="img/accuracy"):
    if not files:
        return []
    return (["", "## Hard cases at 16 spp", "", "Left to right: " + ", ".join(names) + ".", ""]
            + [f"**{s}**\n\n![{s}]({img}/{fn})\n" for s, fn in files])


def training_section(curves, logs, img="img/accuracy"):
    if not curves:
        return []
    return (["", "## Training", "", f"![training curves]({img}/training.png)", "",
             "| run | steps | training minutes | final validation loss |", "|---|---:|---:|---:|"]
            + [f"| {n} | {r['step']} | {float(r['train_seconds']) / 60:.0f} | {float(r['val_loss']):.4f} |"
               for n, r in curves]
            + ["", "The paper's claims, checked on these runs (same width 0.125, same budget):", ""]
            + [f"- {line}" for line in claims(logs)])


def markdown(m, tests, manifest, denoisers, labels, threads, where, extra, page=None):
    """The report, from the measurements `m` and the sections that need more than them
    (`extra`: timing, aux, strips and training lines, in that order). `page`: the title,
    the command that regenerates it and the image folder (parse_args' defaults when None)."""
    page = page or PAGE
    spps = sorted({r["spp"] for r in m.rows})
    scenes = [r["name"] for r in tests]
    return (header(tests, manifest, threads, where, page)
            + targets(denoisers, spps, m.values, m.geomean, m.mean)
            + family_section(m, denoisers, spps) + reference_noise_section(m, denoisers, spps)
            + verdict_section(m, spps, labels)
            + per_scene_section(m, denoisers, spps, scenes) + border_section(m, denoisers, spps)
            + dark_section(m, denoisers, spps) + spp_tables(m, denoisers, spps) + error_vs_time_section(m, denoisers, spps, page["img"])
            + extra)



def page_of(a) -> dict:
    """The title, command and image folder of the page `a` (parse_args' options) asks for;
    options a caller's namespace lacks keep PAGE's values."""
    return {k: getattr(a, k, None) or v for k, v in PAGE.items()}


def parse_args(argv):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", required=True)
    ap.add_argument("--temc", required=True, help="the temc binary")
    ap.add_argument("--model", action="append", default=[], help="an ONNX model (repeatable)")
    ap.add_argument("--runs", help="training runs folder (log.csv per run) for the training curves")
    ap.add_argument("--out", required=True, help="the Markdown report")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--timing-size", default="1920x1080", help='"WxH", or "none" to skip timing')
    ap.add_argument("--title", default=PAGE["title"])
    ap.add_argument("--command", default=PAGE["command"], help="the command the page names for "
                    "regenerating it")
    ap.add_argument("--img", default=PAGE["img"], help="the image folder, relative to --out's")
    ap.add_argument("--about", default=PAGE["about"], help="what the test scenes are (the header)")
    ap.add_argument("--renders", default=PAGE["renders"],
                    help="where the render seconds come from (the header)")
    ap.add_argument("--strips", default=",".join(HARD),
                    help="comma-separated test scenes whose 16-spp results become image strips")
    ap.add_argument("--generated", type=int, default=32,
                    help="generated test scenes to measure: the first N finished, by index (every "
                    "named-* and holdout-* scene is always measured); keeps one run under an hour "
                    "on 2 cores as the test split grows to 100 seeds")
    ap.add_argument("--aux-model", help="the model whose aux modes are compared (default: the "
                    "first --model named temc2-balanced.onnx, else the first)")
    return ap.parse_args(argv)


def read_test_scenes(root, generated=None):
    """The manifest and the test scenes to measure: every hand-written and held-out-family
    scene, and the first `generated` (all when None) of the generator's seeds by index."""
    with open(os.path.join(root, "manifest.json")) as f:
        manifest = json.load(f)
    # Each record carries the reference's sample count, for its prefix (reference_noise).
    ref_spp = manifest.get("options", {}).get("ref_spp")
    tests = [dict(r, ref_spp=ref_spp) for r in manifest["scenes"] if r["split"] == "test"]
    seeds = sorted((r for r in tests if r["name"].startswith("scene-")), key=lambda r: r["name"])
    keep = {r["name"] for r in seeds[:generated]}
    tests = [r for r in tests if not r["name"].startswith("scene-") or r["name"] in keep]
    if not tests:
        raise SystemExit("no finished test scenes in the data set yet")
    return manifest, tests


def pyplot():
    """matplotlib's pyplot on the Agg backend, or a clear exit when matplotlib is missing.
    Checked by type, not by import: colour-science puts a MagicMock into
    sys.modules["matplotlib"] when matplotlib is absent, so the import alone succeeds and
    the report would draw nothing (issue 34)."""
    import types

    try:
        import matplotlib
    except ImportError:
        matplotlib = None
    if not isinstance(matplotlib, types.ModuleType) or not getattr(matplotlib, "__file__", None):
        raise SystemExit("the report needs matplotlib, which is not installed in this Python: "
                         "pip install -r training/requirements.txt")
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def report(a, models, aux, oidn_denoise=None, oidn_time=None, where=None):
    """Measures and writes the report for the options `a` (parse_args'). `models`: per temc
    model (name, denoiser, bench: threads -> seconds); `aux`: (name, denoiser) of the model
    whose aux modes are compared, or None. OIDN's denoiser and timing are parameters so that
    a machine without pyoidn can run the rest (default: pyoidn's); `where` is the header's
    machine line (default: this machine's, today)."""
    oidn_denoise, oidn_time = oidn_denoise or oidn_denoiser, oidn_time or oidn_timing
    plt = pyplot()

    page = page_of(a)
    img_dir = os.path.join(os.path.dirname(os.path.abspath(a.out)), page["img"])
    os.makedirs(img_dir, exist_ok=True)
    manifest, tests = read_test_scenes(a.data, a.generated)
    labels = [name for name, _, _ in models]
    denoisers = ["noisy"] + labels + list(OIDN)
    runs = {name: run for name, run, _ in models}
    runs.update((name, oidn_denoise(q)) for name, q in OIDN.items())
    strip_scenes = getattr(a, "strips", None)
    rows, aux_rows, strips = measure(a.data, tests, runs, aux,
                                     strip_scenes.split(",") if strip_scenes else HARD)
    write_csv(os.path.join(img_dir, "measurements.csv"), rows)
    m = Means(rows)
    plot_error_vs_time(plt, denoisers, sorted({r["spp"] for r in rows}), m,
                       os.path.join(img_dir, "error-vs-time.png"))
    timing = ([] if a.timing_size == "none" else
              timings({name: b for name, _, b in models}, a.threads, a.timing_size, oidn_time))
    strip_names = ["noisy", "OIDN high"] + labels + ["reference"]
    strip_files = write_strips(strips, strip_names, img_dir)
    curves, logs = read_training_logs(a.runs) if a.runs else ([], {})
    if a.runs:
        plot_training(plt, logs, os.path.join(img_dir, "training.png"))
    if aux_rows:
        write_csv(os.path.join(img_dir, "aux-modes.csv"), aux_rows)
    extra = (timing_section(a.timing_size, timing) + aux_section(aux and aux[0], aux_rows)
             + strips_section(strip_names, strip_files, page["img"])
             + training_section(curves, logs, page["img"]))
    md = markdown(m, tests, manifest, denoisers, labels, a.threads, where or machine(), extra, page)
    with open(a.out, "w") as f:
        f.write("\n".join(md) + "\n")
    print(f"wrote {a.out}")


def main(argv=None):
    a = parse_args(argv)
    names = distinct_labels([model_label(a.temc, m)[0] for m in a.model], a.model)
    models = [(name, temc_denoiser(a.temc, m, a.threads),
               None if a.timing_size == "none" else temc_bench(a.temc, m, a.timing_size))
              for name, m in zip(names, a.model)]
    aux_model = a.aux_model or next((m for m in a.model if m.endswith("temc2-balanced.onnx")),
                                    a.model[0] if a.model else None)
    aux = (model_label(a.temc, aux_model)[0], temc_denoiser(a.temc, aux_model, a.threads)) if aux_model else None
    report(a, models, aux)


if __name__ == "__main__":
    main()
