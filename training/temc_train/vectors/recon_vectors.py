"""Writes tests/data/recon_vectors.json: small reconstruction cases, their inputs and the
float64 PyTorch result, so the Rust core (reconstruct::tests) and this module
(tests/test_reconstruct.py) check themselves against one reference.

Run from training/: python -m temc_train.vectors.recon_vectors. Inputs are written as short
decimals that both sides read as float32; non-finite values as "nan", "inf", "-inf".
"""

import argparse
import json
import math
import pathlib

import numpy as np
import torch

from ..reconstruct import LOGIT_MAX, channels, reconstruct

OUT = pathlib.Path(__file__).resolve().parents[3] / "tests" / "data" / "recon_vectors.json"
TOLERANCE = 1e-5
SPECIALS = [math.nan, math.inf, -math.inf, 1e30, -1e30, 3e38, 88.0, -88.0, 2e4]


def _case(name, rng, h, w, levels, kernel, demodulate=False, ldr=False, sd=2.0, guide=False,
          fixed_range=False, exposure=1.0, upsample="nearest", coarse_clamp=False, range_noise=0.0,
          coarse_gain=1.0, coarse_radius=0, coarse_sparse=0.0):
    """Random inputs for one case: rgb in [0, 2), albedo with some zeros, logits ~ N(0, sd)."""
    rgb = np.round(2.0 * rng.random((3, h, w)) ** 2, 4)
    albedo = np.where(rng.random((3, h, w)) < 0.15, 0.0, np.round(rng.random((3, h, w)), 4))
    filters = [
        np.round(sd * rng.standard_normal((channels(kernel, guide), h >> l, w >> l)), 2)
        for l in range(levels)
    ]
    return dict(name=name, h=h, w=w, levels=levels, kernel=kernel, demodulate=demodulate,
                eps=0.01, ldr=ldr, guide=guide, fixed_range=fixed_range, exposure=exposure,
                upsample=upsample, range_opening="plain", coarse_clamp=coarse_clamp,
                range_noise=range_noise, coarse_gain=coarse_gain, coarse_radius=coarse_radius,
                coarse_sparse=coarse_sparse,
                rgb=rgb,
                albedo=albedo if demodulate else None, aux=None, filters=filters)


def cases():
    """The cases: sizes, levels, kernels, modes, and the inputs that break naive code."""
    rng = np.random.default_rng(14)
    out = [
        _case("box_8x8_L1_k3", rng, 8, 8, 1, 3, sd=0.0),
        _case("random_8x8_L1_k5", rng, 8, 8, 1, 5),
        _case("random_16x8_L2_k3", rng, 16, 8, 2, 3),
        _case("random_8x8_L3_k3", rng, 8, 8, 3, 3),
        _case("random_16x8_L3_k5", rng, 16, 8, 3, 5, sd=1.0),
        _case("demod_8x8_L2_k3", rng, 8, 8, 2, 3, demodulate=True),
        _case("ldr_8x16_L2_k3", rng, 8, 16, 2, 3, ldr=True),
        _case("demod_ldr_8x8_L3_k5", rng, 8, 8, 3, 5, demodulate=True, ldr=True),
        _case("sharp_8x8_L2_k3", rng, 8, 8, 2, 3, sd=30.0),
    ]
    c = _case("extreme_logits_8x8_L2_k3", rng, 8, 8, 2, 3)
    for f in c["filters"]:
        pick = rng.random(f.shape) < 0.3
        f[pick] = rng.choice(SPECIALS, size=int(pick.sum()))
    out.append(c)
    c = _case("firefly_16x8_L3_k3", rng, 16, 8, 3, 3)
    c["rgb"][:, 5, 3] = [60.0, 45.0, 30.0]
    out.append(c)
    c = _case("hdr_8x8_L2_k3_demod", rng, 8, 8, 2, 3, demodulate=True)
    c["rgb"][:, 2:4, 2:6] = 65504.0
    c["albedo"][:, 2:4, 2:6] = 1.0
    out.append(c)
    # A black pixel under a one-hot chroma kernel and a wide luma kernel: the grey fallback.
    c = _case("grey_fallback_8x8_L1_k3", rng, 8, 8, 1, 3, sd=0.5)
    c["rgb"][:, 4, 4] = 0.0
    c["filters"][0][9:18, 4:5, 4:5] = -LOGIT_MAX
    c["filters"][0][13, 4, 4] = LOGIT_MAX
    out.append(c)
    out.append(_case("guide_8x8_L1_k5", rng, 8, 8, 1, 5, guide=True))
    out.append(_case("guide_demod_16x8_L3_k3", rng, 16, 8, 3, 3, demodulate=True, guide=True))
    # A lamp the guide fences off: its pixels' guides are 6 apart from the rest.
    c = _case("guide_lamp_8x8_L2_k3", rng, 8, 8, 2, 3, sd=0.5, guide=True)
    c["rgb"][:, 2:4, 2:4] = 500.0
    c["filters"][0][-2:] = 0.0
    c["filters"][0][-2:, 2:4, 2:4] = 6.0
    out.append(c)
    c = _case("guide_extreme_8x8_L1_k3", rng, 8, 8, 1, 3, guide=True)
    pick = rng.random(c["filters"][0][-2:].shape) < 0.4
    c["filters"][0][-2:][pick] = rng.choice(SPECIALS, size=int(pick.sum()))
    out.append(c)
    # The fixed range term: a 4x4 lamp 250x its surroundings, every logit pulling toward
    # it; a firefly it must not fence off; random cases with guides, levels, demodulation.
    c = _case("fixed_lamp_16x16_L1_k5", rng, 16, 16, 1, 5, sd=0.5, fixed_range=True, exposure=0.5)
    c["rgb"][:, 4:8, 4:8] = 500.0
    c["filters"][0][:50] += np.where(np.arange(50) % 25 < 12, 8.0, 0.0)[:, None, None]
    out.append(c)
    c = _case("fixed_firefly_16x8_L1_k5", rng, 16, 8, 1, 5, sd=0.5, fixed_range=True, exposure=2.0)
    c["rgb"][:, 7, 3] = 900.0
    out.append(c)
    out.append(_case("fixed_guide_16x8_L2_k3", rng, 16, 8, 2, 3, guide=True, fixed_range=True,
                     exposure=3.0))
    out.append(_case("fixed_demod_8x8_L3_k3", rng, 8, 8, 3, 3, demodulate=True, fixed_range=True,
                     exposure=0.25))
    # Bilinear composition: odd coarse sizes (edges replicated on both sides), the full
    # shipped recipe, and a lamp whose coarse correction must spread, not step.
    out.append(_case("bilinear_16x8_L2_k3", rng, 16, 8, 2, 3, upsample="bilinear"))
    out.append(_case("bilinear_24x8_L3_k5", rng, 24, 8, 3, 5, sd=1.0, upsample="bilinear"))
    out.append(_case("bilinear_full_16x16_L3_k5", rng, 16, 16, 3, 5, guide=True,
                     fixed_range=True, exposure=0.5, upsample="bilinear"))
    c = _case("bilinear_lamp_16x16_L2_k3", rng, 16, 16, 2, 3, sd=0.5, upsample="bilinear")
    c["rgb"][:, 6:8, 6:8] = 40.0  # brighter, and float32 cancellation nears the tolerance
    out.append(c)
    return (out + aux_opening_cases(rng) + coarse_clamp_cases(rng) + chroma_cap_cases(rng)
            + range_noise_cases(rng) + coarse_mean_cases(rng) + coarse_sparse_cases(rng))


def coarse_clamp_cases(rng):
    """The coarse clamp: a firefly on a dark floor (the coarse levels' correction capped),
    and the whole recipe of a multi-level model with it, both compositions."""
    out = []
    c = _case("clamp_firefly_16x16_L3_k3", rng, 16, 16, 3, 3, sd=0.5, coarse_clamp=True)
    c["rgb"] *= 0.01
    c["rgb"][:, 9, 6] = 700.0
    out.append(c)
    for name, up in (("clamp_full_16x16_L3_k5", "nearest"), ("clamp_full_24x8_L2_k3", "bilinear")):
        h, w, levels, kernel = (16, 16, 3, 5) if up == "nearest" else (24, 8, 2, 3)
        c = _case(name, rng, h, w, levels, kernel, sd=1.0, guide=True, fixed_range=True,
                  exposure=0.5, upsample=up, coarse_clamp=True)
        c.update(range_opening="aux", aux=_aux(rng, h, w))
        out.append(c)
    return out


def _aux(rng, h, w, patches=6):
    """[7, h, w] aux planes of a few flat surfaces (albedo, normal, depth in [0, 1]) with
    their edges where the patches meet."""
    aux = np.zeros((7, h, w))
    aux[:] = np.round(rng.random((7, 1, 1)), 3)
    for _ in range(patches):
        y, x = rng.integers(0, h), rng.integers(0, w)
        aux[:, y:y + rng.integers(2, 6), x:x + rng.integers(2, 6)] = np.round(rng.random((7, 1, 1)) * 0.9, 3)
    return aux


def aux_opening_cases(rng):
    """The aux-guided opening (range_opening "aux"): a 1 px lamp with an emitter's albedo
    on a surface (kept), a firefly on that surface and one on a lone non-emitter texel
    (both opened away), a 2x2 lamp the aux outlines, and random multi-level cases."""
    out = []
    c = _case("aux_lamp_16x16_L1_k5", rng, 16, 16, 1, 5, sd=0.5, fixed_range=True, exposure=0.5)
    c.update(range_opening="aux", aux=_aux(rng, 16, 16, 0))
    c["rgb"][:, 5, 5] = 800.0  # the lamp: an emitter's albedo, its own normal
    c["aux"][:3, 5, 5] = 1.0
    c["aux"][3:6, 5, 5] = 0.1
    c["rgb"][:, 11, 11] = 900.0  # a firefly on the surface
    c["rgb"][:, 3, 12] = 700.0  # a firefly on a lone texel
    c["aux"][:3, 3, 12] = 0.3
    out.append(c)
    c = _case("aux_lamp2_16x8_L2_k3", rng, 16, 8, 2, 3, sd=0.5, fixed_range=True, exposure=2.0)
    c.update(range_opening="aux", aux=_aux(rng, 16, 8, 0))
    c["rgb"][:, 6:8, 2:4] = 500.0
    c["aux"][:3, 6:8, 2:4] = 0.8
    out.append(c)
    for name, h, w, levels, kernel, up in (("aux_random_16x16_L3_k5", 16, 16, 3, 5, "nearest"),
                                          ("aux_random_24x8_L2_k3", 24, 8, 2, 3, "bilinear")):
        c = _case(name, rng, h, w, levels, kernel, sd=1.0, guide=True, fixed_range=True,
                  exposure=0.7, upsample=up)
        c.update(range_opening="aux", aux=_aux(rng, h, w))
        c["rgb"] *= np.where(rng.random((1, h, w)) < 0.1, 300.0, 1.0)
        out.append(c)
    return out


def run(case, dtype):
    """The torch result for one case (inputs rounded to float32 first, like Rust reads them)."""
    t = lambda a: torch.from_numpy(np.asarray(a, np.float32).astype(np.float64)).to(dtype)[None]
    albedo = None if case["albedo"] is None else t(case["albedo"])
    aux = None if case["aux"] is None else t(case["aux"])
    out = reconstruct(t(case["rgb"]), albedo, [t(f) for f in case["filters"]], case["kernel"],
                      case["demodulate"], case["eps"], case["ldr"], case["guide"],
                      case["fixed_range"], case["exposure"], case["upsample"],
                      case["range_opening"], aux, case["coarse_clamp"], case["range_noise"],
                      case["coarse_gain"], case["coarse_radius"], case["coarse_sparse"])
    return out[0].double().numpy()


def _num(v):
    v = float(v)
    if math.isnan(v):
        return "nan"
    if math.isinf(v):
        return "inf" if v > 0 else "-inf"
    return v


def _flat(a, digits=None):
    return [_num(float(f"{v:.{digits}g}") if digits else v) for v in np.asarray(a).ravel()]


def chroma_cap_cases(rng):
    """The chroma composition's common cap (step 4): an orange bright pixel with little blue
    in a 2x2 block of warm dark ones, the fine chroma kernel one-hot on the centre, the
    coarse one a box, blends open. The coarse correction drives the dark pixels' red and
    green far below zero but not their blue; before the cap they came out pure blue (0, 0,
    2.1), now near grey (0.151, 0.152, 0.149)."""
    c = _case("chroma_cap_8x8_L2_k3", rng, 8, 8, 2, 3, sd=0.0)
    c["rgb"][:] = np.array([0.1, 0.08, 0.05])[:, None, None]
    c["rgb"][:, 2, 2] = [4.0, 2.4, 0.1]
    c["filters"][0][9:18] = -LOGIT_MAX
    c["filters"][0][13] = LOGIT_MAX
    c["filters"][0][18:20] = LOGIT_MAX
    return [c]


def range_noise_cases(rng):
    """The fixed range term's threshold from local noise (`temc.range_noise`): a clean bright
    floor crossed by a one-pixel shadow line 1.7 stops darker (a clean image: the line is an
    edge), and the shipped recipe of a 3-level model with it on noisy random radiance."""
    c = _case("range_noise_shadow_16x16_L2_k3", rng, 16, 16, 2, 3, sd=0.5, fixed_range=True,
              exposure=0.2, range_noise=4.0)
    c["rgb"] = np.round(5.0 + 0.01 * rng.random((3, 16, 16)), 4)
    c["rgb"][:, :, 8] = 1.5
    out = [c]
    c = _case("range_noise_full_16x16_L3_k5", rng, 16, 16, 3, 5, sd=1.0, guide=True,
              fixed_range=True, exposure=0.7, upsample="bilinear", coarse_clamp=True,
              range_noise=4.0)
    c.update(range_opening="aux", aux=_aux(rng, 16, 16))
    c["rgb"] *= np.where(rng.random((1, 16, 16)) < 0.1, 30.0, 1.0)
    out.append(c)
    return out


def coarse_mean_cases(rng):
    """The coarse clamp against a local mean (`temc.coarse_gain`, `temc.coarse_radius`): sparse
    1-spp-like radiance (most pixels black, some 30x brighter) under nearest and bilinear
    composition, and the shipped recipe with it (radius 2 reaches past a 16x8 level-1 edge,
    so the replicated edges count)."""
    out = []
    for name, up, levels, k, gain, radius in (("coarse_mean_16x16_L2_k3", "nearest", 2, 3, 0.5, 1),
                                               ("coarse_mean_16x8_L3_k5", "bilinear", 3, 5, 0.75, 2)):
        h, w = 16, 16 if levels == 2 else 8
        c = _case(name, rng, h, w, levels, k, sd=1.0, upsample=up, coarse_clamp=True,
                  coarse_gain=gain, coarse_radius=radius)
        c["rgb"] *= np.where(rng.random((1, h, w)) < 0.6, 0.0, 1.0)
        c["rgb"] *= np.where(rng.random((1, h, w)) < 0.1, 30.0, 1.0)
        out.append(c)
    c = _case("coarse_mean_full_16x16_L3_k5", rng, 16, 16, 3, 5, sd=1.0, guide=True,
              fixed_range=True, exposure=0.7, upsample="bilinear", coarse_clamp=True,
              range_noise=6.0, coarse_gain=0.75, coarse_radius=2)
    c.update(range_opening="aux", aux=_aux(rng, 16, 16))
    c["rgb"] *= np.where(rng.random((1, 16, 16)) < 0.5, 0.0, 1.0)
    out.append(c)
    return out


def coarse_sparse_cases(rng):
    """The coarse clamp's rise where samples are sparse (`temc.coarse_sparse`): radiance with
    most pixels exactly black, so the lit share ranges from 0 to 1 across the windows (the
    rise from 1 to its bound), under nearest composition, and the shipped recipe with it
    (radius 4 is wider than the 8x8 level 1, so the replicated edges count)."""
    c = _case("coarse_sparse_16x16_L2_k3", rng, 16, 16, 2, 3, sd=1.0, coarse_clamp=True,
              coarse_gain=0.5, coarse_radius=1, coarse_sparse=0.5)
    c["rgb"] *= np.where(rng.random((1, 16, 16)) < 0.8, 0.0, 1.0)
    c["rgb"][:, :4] = 0.0
    out = [c]
    c = _case("coarse_sparse_full_16x16_L3_k5", rng, 16, 16, 3, 5, sd=1.0, guide=True,
              fixed_range=True, exposure=0.7, upsample="bilinear", coarse_clamp=True,
              range_noise=6.0, coarse_gain=0.5, coarse_radius=4, coarse_sparse=0.5)
    c.update(range_opening="aux", aux=_aux(rng, 16, 16))
    c["rgb"] *= np.where(rng.random((1, 16, 16)) < 0.7, 0.0, 1.0)
    out.append(c)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.parse_args(argv)  # --help; no options
    doc = {"tolerance": TOLERANCE, "logit_max": LOGIT_MAX, "cases": []}
    for case in cases():
        out = run(case, torch.float64)
        entry = {k: v for k, v in case.items() if k not in ("rgb", "albedo", "aux", "filters")}
        entry["rgb"] = _flat(case["rgb"])
        entry["albedo"] = None if case["albedo"] is None else _flat(case["albedo"])
        entry["aux"] = None if case["aux"] is None else _flat(case["aux"])
        entry["filters"] = [_flat(f) for f in case["filters"]]
        entry["out"] = _flat(out, 10)
        doc["cases"].append(entry)
    OUT.write_text(json.dumps(doc, separators=(",", ":")) + "\n")
    print(f"wrote {OUT} ({OUT.stat().st_size} bytes, {len(doc['cases'])} cases)")


if __name__ == "__main__":
    main()
