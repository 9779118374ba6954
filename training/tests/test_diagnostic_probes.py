"""The diagnostic probes: reference_noise.py on a data set whose renders are Gaussian draws
of known variance (every noisy input must come out at ref_spp / spp + 1 reference
variances), worst_pixels.py on an image with one kept dot, and constants.py's variants
(set inside their block only, unknown names refused, a --base under every one)."""

import json

import numpy as np

from temc_train.probes import reference_noise

from test_data_train import fake_scene, write_exr


def test_noisy_inputs_sit_at_the_expected_multiples_of_the_reference_noise(tmp_path):
    rng = np.random.default_rng(11)
    n, k, spps, sigma = 512, 64, (16, 64), 0.8
    records = []
    for i in range(2):
        name = f"scene-{i:05}"
        d = tmp_path / "test" / name
        d.mkdir(parents=True)
        _, clean = fake_scene(rng, 0.0)
        truth = clean["color"].astype(np.float64)
        draw = lambda s: truth + sigma / np.sqrt(s) * rng.standard_normal(truth.shape)  # noqa: E731
        prefix, rest = draw(k), draw(n - k)
        for fname, img in [("ref.exr", (k * prefix + (n - k) * rest) / n),
                           ("ref-spp0064.exr", prefix)] + [(f"spp{s:04}.exr", draw(s)) for s in spps]:
            write_exr(d / fname, {**clean, "color": img.astype(np.float32)})
        records.append({"name": name, "split": "test", "dir": f"test/{name}", "reference": "ref.exr",
                        "noisy": [[s, f"spp{s:04}.exr"] for s in spps],
                        "reference_prefixes": [[k, "ref-spp0064.exr"]]})
    (tmp_path / "manifest.json").write_text(
        json.dumps({"scenes": records, "options": {"ref_spp": n, "spp": list(spps)}}))
    md = reference_noise.table(str(tmp_path))
    assert md[0].startswith("| scene | sampling |") and "(expected 33)" in md[0]
    for line in md[2:4]:
        cells = [float(c) for c in line.strip("|").split("|")[3:]]
        assert abs(cells[0] / 33 - 1) < 0.1 and abs(cells[1] / 9 - 1) < 0.1, line
    assert md[-1].startswith("2 of 2 scenes within 25 %")


def test_worst_pixels_finds_a_kept_firefly():
    from temc_train import evaluate as ev
    from temc_train.probes import worst_pixels

    rng = np.random.default_rng(2)
    ref = rng.uniform(0.2, 0.4, (16, 12, 3))
    x = ref * rng.uniform(0.95, 1.05, ref.shape)
    x[5, 7] = 30.0  # a dot the reconstruction kept
    assert abs(worst_pixels.pixel_errors(x, ref).mean() - ev.relmse(x, ref)) < 1e-12
    (pixel, share), *_ = worst_pixels.worst(x, ref, 3)
    assert pixel == (5, 7) and share > 0.99


def test_a_constants_variant_is_set_only_inside_its_block_and_unknown_names_are_refused():
    from temc_train import keep_mean, reconstruct
    from temc_train.probes import constants

    variant = constants.parse_variant("reconstruct.COARSE_GAIN=2;keep_mean.BLOCK=32")
    before = (reconstruct.COARSE_GAIN, keep_mean.BLOCK)
    with constants.patched(variant):
        assert (reconstruct.COARSE_GAIN, keep_mean.BLOCK) == (2.0, 32)
        assert isinstance(keep_mean.BLOCK, int)  # a block size stays an int
    assert (reconstruct.COARSE_GAIN, keep_mean.BLOCK) == before
    for bad in ("reconstruct.NO_SUCH=1", "numpy.pi=3", "reconstruct.RANGE_OPENINGS=1"):
        assert refused(bad), bad


def test_a_recon_setting_is_a_variant_too():
    from temc_train.probes import constants

    assert constants.parse_variant("recon.coarse_radius=4;recon.coarse_gain=0.5") == [
        (None, "coarse_radius", 4), (None, "coarse_gain", 0.5)]
    assert constants.parse_variant("recon.fixed_range=0;recon.range_opening=plain") == [
        (None, "fixed_range", False), (None, "range_opening", "plain")]
    for bad in ("recon.guide=1", "recon.upsample=2", "recon.no_such=1", "recon.kernel=3",
                "recon.coarse_clamp=0.5", "recon.range_noise=x"):
        assert refused(bad), bad


def refused(variant: str) -> bool:
    """Whether probes.constants refuses the variant (it exits with a message)."""
    from temc_train.probes import constants

    try:
        constants.parse_variant(variant)
    except SystemExit:
        return True
    return False


def test_a_constants_base_applies_to_the_baseline_and_under_every_variant(monkeypatch):
    from temc_train import reconstruct
    from temc_train.probes import constants

    seen = []

    def denoise_variants(model, recons, noisy, aux, scale):
        seen.append(recons[0]["coarse_sparse"])
        return [np.zeros_like(noisy)]

    monkeypatch.setattr(reconstruct, "denoise_variants", denoise_variants)
    layers = {"color": np.ones((4, 4, 3), np.float32), "albedo": np.ones((4, 4, 3), np.float32),
              "normal": np.ones((4, 4, 3), np.float32), "depth": np.ones((4, 4), np.float32)}
    variants = [constants.parse_variant("recon.coarse_sparse=0.7"),
                constants.parse_variant("recon.coarse_gain=2")]
    constants.image_errors(None, {"coarse_sparse": 0.5}, layers, layers["color"], variants,
                           constants.parse_variant("recon.coarse_sparse=0"))
    assert seen == [0.0, 0.7, 0.0]  # the base under both; a variant's own setting wins
