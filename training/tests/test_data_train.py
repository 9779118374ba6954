"""The data loader and the resumable training loop, on a tiny synthetic data set laid
out like `temc-render dataset` output."""

import json
import os

import numpy as np
import pytest
import torch

from temc_train import data
from temc_train.drivers import export, train
from temc_train.models import build
from temc_train.reconstruct import reconstruct

SIZE = 32


def write_exr(path, layers):
    import Imath
    import OpenEXR

    h, w = layers["color"].shape[:2]
    header = OpenEXR.Header(w, h)
    ch = {}
    pix = {}
    for layer, comps in (("color", "RGB"), ("albedo", "RGB"), ("normal", "XYZ")):
        for i, c in enumerate(comps):
            ch[f"{layer}.{c}"] = Imath.Channel(Imath.PixelType(Imath.PixelType.FLOAT))
            pix[f"{layer}.{c}"] = np.ascontiguousarray(layers[layer][..., i], np.float32).tobytes()
    ch["depth.Z"] = Imath.Channel(Imath.PixelType(Imath.PixelType.FLOAT))
    pix["depth.Z"] = np.ascontiguousarray(layers["depth"], np.float32).tobytes()
    header["channels"] = ch
    f = OpenEXR.OutputFile(str(path), header)
    f.writePixels(pix)
    f.close()


def fake_scene(rng, noise):
    yy, xx = np.mgrid[0:SIZE, 0:SIZE] / SIZE
    ref = np.stack([0.2 + 0.6 * xx, 0.3 + 0.3 * yy, 0.5 * np.ones_like(xx)], -1).astype(np.float32)
    n = np.stack([xx - 0.5, yy - 0.5, np.ones_like(xx)], -1)
    layers = {
        "albedo": ref.clip(0, 1),
        "normal": (n / np.linalg.norm(n, axis=-1, keepdims=True)).astype(np.float32),
        "depth": (1 + xx).astype(np.float32),
    }
    noisy = {**layers, "color": (ref * rng.exponential(1.0, ref.shape) ** noise).astype(np.float32)}
    return noisy, {**layers, "color": ref}


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    root = tmp_path_factory.mktemp("ds")
    rng = np.random.default_rng(1)
    records = []
    for i, split in enumerate(["train", "train", "val"]):
        name = f"scene-{i:05}"
        d = root / split / name
        d.mkdir(parents=True)
        noisy = []
        for spp in (1, 4):
            img, ref = fake_scene(rng, 1.0 / spp)
            write_exr(d / f"spp{spp:04}.exr", img)
            noisy.append([spp, f"spp{spp:04}.exr"])
        write_exr(d / "ref.exr", ref)
        # A noisy reference prefix (Noise2Noise target) on the first scene only.
        prefixes = []
        if i == 0:
            write_exr(d / "ref-spp0002.exr", fake_scene(rng, 0.5)[0])
            prefixes = [[2, "ref-spp0002.exr"]]
        (d / "scene.txt").write_text("camera eye 0 0 -3 target 0 0 0 fov 40\n")
        records.append({"name": name, "split": split, "dir": f"{split}/{name}", "noisy": noisy,
                        "reference": "ref.exr", "reference_prefixes": prefixes,
                        "seconds_noisy": 0, "seconds_reference": 0, "features": ""})
    (root / "manifest.json").write_text(json.dumps({"scenes": records}))
    return str(root)


def test_samples_have_the_network_shapes_and_ranges(dataset):
    scenes = data.load_split(dataset, "train")
    assert len(scenes) == 2 and scenes[0].spp == [1, 4]
    rng = np.random.default_rng(0)
    chroma, luma, aux, noisy, albedo, target = data.batch(scenes, rng, 3, crop=16)
    assert chroma.shape == (3, 2, 16, 16) and luma.shape == (3, 1, 16, 16)
    assert aux.shape == (3, 7, 16, 16)
    assert noisy.shape == albedo.shape == target.shape == (3, 3, 16, 16)
    for x in (chroma, luma, aux, noisy, albedo, target):
        assert x.dtype == np.float32 and np.isfinite(x).all() and x.min() >= 0
    for x in (chroma, luma, aux, albedo):
        assert x.max() <= 1
    # The albedo the reconstruction demodulates by is the network's albedo input.
    assert np.array_equal(albedo, aux[:, :3])


def test_aux_dropout_uses_the_contract_fill(dataset):
    sc = data.load_split(dataset, "train")[0]
    rng = np.random.default_rng(0)
    _, _, aux, *_ = data.make_sample(sc, rng, 16, aux_mode="none")
    assert (aux[:3] == 0).all() and np.allclose(aux[3:6], 0.5) and (aux[6] == 0).all()
    _, _, aux, *_ = data.make_sample(sc, rng, 16, aux_mode="albedo")
    assert aux[:3].max() > 0 and np.allclose(aux[3:6], 0.5)


def test_normals_follow_the_image_transform():
    # Normals that point away from the image centre (camera space: x right, y up) must
    # still do so after every flip and rotation.
    c = 8
    yy, xx = np.mgrid[0:c, 0:c] - (c - 1) / 2
    n = np.stack([xx, -yy, np.zeros_like(xx)], -1).astype(np.float32)  # image y points down
    for flip in (False, True):
        for k in range(4):
            t = data._transform_normal(n, flip, k)
            ty, tx = np.mgrid[0:c, 0:c] - (c - 1) / 2
            assert np.allclose(t[..., 0], tx) and np.allclose(t[..., 1], -ty), (flip, k)


def test_auto_exposure_matches_the_core_rule():
    img = np.full((4, 4, 3), 0.5, np.float32)
    assert data.auto_input_scale(img) == pytest.approx(0.18 / 0.5, rel=1e-6)
    assert data.auto_input_scale(np.zeros((2, 2, 3), np.float32)) == 1.0


def test_camera_frame_matches_the_renderer():
    # Looking along +z in a right-handed world with y up, +x lies on the camera's left
    # (render/src/camera.rs).
    f = data.camera_frame("camera eye 0 0 -3 target 0 0 0 fov 40")
    assert np.allclose(f, [[-1, 0, 0], [0, 1, 0], [0, 0, -1]], atol=1e-6)


def test_training_resumes_and_exports(dataset, tmp_path):
    run = str(tmp_path / "run")
    args = ["--data", dataset, "--arch", "ae", "--width", "0.0625", "--run", run,
            "--crop", "32", "--batch", "2", "--val-minutes", "0", "--threads", "1"]
    train.main(args + ["--max-steps", "2"])
    ck = torch.load(os.path.join(run, "checkpoint.pt"), weights_only=False)
    assert ck["state"]["step"] == 2
    train.main(args + ["--max-steps", "4"])
    ck = torch.load(os.path.join(run, "checkpoint.pt"), weights_only=False)
    assert ck["state"]["step"] == 4
    rows = open(os.path.join(run, "log.csv")).read().splitlines()
    assert rows[0].startswith("step") and rows[-1].startswith("4,")
    model, arch, width, info = export.load_checkpoint(os.path.join(run, "model.pt"))
    assert (arch, width, info["train_steps"]) == ("ae", 0.0625, 4)


def test_a_run_gains_the_guide_on_resume_and_keeps_its_outputs(dataset, tmp_path):
    # Resuming a run without guide channels with --guide 1 keeps every trained weight and
    # Adam moment; the new guide rows start small, so the filters barely move.
    run = str(tmp_path / "run")
    args = ["--data", dataset, "--arch", "temc2", "--width", "0.0625", "--levels", "1", "--run", run,
            "--crop", "32", "--batch", "2", "--val-minutes", "0", "--threads", "1"]
    train.main(args + ["--max-steps", "2"])
    before, *_ = export.load_checkpoint(os.path.join(run, "model.pt"))
    ck = torch.load(os.path.join(run, "checkpoint.pt"), weights_only=False)
    grown = build("temc2", 0.0625, 1, 5, "both", True)
    train.add_guide(grown, ck)
    xs = [torch.rand(1, c, 32, 32) for c in (2, 1, 7)]
    with torch.no_grad():
        old, new = before.eval()(*xs)[0], grown.eval()(*xs)[0]
    assert new.shape[1] == old.shape[1] + 2
    assert torch.equal(new[:, :old.shape[1]], old)
    assert 0 < float(new[:, old.shape[1]:].abs().max()) < 1.0
    train.main(args + ["--guide", "1", "--max-steps", "3"])
    ck = torch.load(os.path.join(run, "checkpoint.pt"), weights_only=False)
    assert ck["recon"]["guide"] and ck["state"]["step"] == 3 and ck["opt"] is not None


def test_a_run_grows_coarser_levels_on_resume_and_starts_near_its_output(dataset, tmp_path):
    # Resuming a one-level run with --levels 3 keeps every trained weight and Adam moment by
    # name; the new heads start at zero and the finest blend near 0, so the reconstructed
    # image moves by about sigmoid(GROWN_BLEND_LOGIT) of the coarse levels' difference.
    run = str(tmp_path / "run")
    args = ["--data", dataset, "--arch", "temc2", "--width", "0.0625", "--run", run, "--crop", "32",
            "--batch", "2", "--val-minutes", "0", "--threads", "1", "--guide", "1"]
    train.main(args + ["--levels", "1", "--max-steps", "3"])
    before, *_ = export.load_checkpoint(os.path.join(run, "model.pt"))
    ck = torch.load(os.path.join(run, "checkpoint.pt"), weights_only=False)
    grown = build("temc2", 0.0625, 3, 5, "both", True)
    train.add_levels(grown, ck)
    old_params = dict(before.named_parameters())
    for name, p in grown.named_parameters():
        if name in old_params and not name.startswith("decoder.heads.convs.0.bias"):
            assert torch.equal(p, old_params[name]), name
    xs = [torch.rand(1, c, 32, 32) for c in (2, 1, 7)]
    rgb = torch.rand(1, 3, 32, 32) * torch.rand(1, 1, 32, 32) ** 4 * 10
    with torch.no_grad():
        old = reconstruct(rgb, None, before.eval()(*xs), 5, guide=True)
        new = reconstruct(rgb, None, grown.eval()(*xs), 5, guide=True)
    change = float((new - old).abs().mean() / old.abs().mean())
    assert 1e-4 < change < 0.03, change
    train.main(args + ["--levels", "3", "--max-steps", "5"])
    ck = torch.load(os.path.join(run, "checkpoint.pt"), weights_only=False)
    assert ck["recon"]["levels"] == 3 and ck["state"]["levels_from"] == [3, 1]
    assert ck["state"]["step"] == 5 and ck["opt"] is not None
    with pytest.raises(SystemExit):  # and it does not shrink back
        train.main(args + ["--levels", "2", "--max-steps", "6"])
    # --blend-logit opens the finest blend once: a later resume with it trains on.
    train.main(args + ["--levels", "3", "--max-steps", "6", "--blend-logit", "-1"])
    ck = torch.load(os.path.join(run, "checkpoint.pt"), weights_only=False)
    assert ck["state"]["blend_reset"] == [5, -1.0]
    moved = ck["model"]["decoder.heads.convs.0.bias"][50:52]
    assert torch.all((moved + 1.0).abs() < 0.01) and torch.any(moved != -1.0), moved
    train.main(args + ["--levels", "3", "--max-steps", "7", "--blend-logit", "-1"])
    ck = torch.load(os.path.join(run, "checkpoint.pt"), weights_only=False)
    assert ck["state"]["blend_reset"] == [5, -1.0]  # not set again at step 6


def test_a_non_finite_step_is_skipped_not_taken(dataset, tmp_path, monkeypatch):
    # A NaN gradient would turn every weight to NaN and then overwrite the checkpoint (a
    # grown run did at 20,700 CPU s): the step is dropped and counted instead.
    calls = []
    real = train.training_loss

    def sometimes_nan(*args):
        calls.append(1)
        loss = real(*args)
        return loss * float("nan") if len(calls) == 2 else loss
    monkeypatch.setattr(train, "training_loss", sometimes_nan)
    run = str(tmp_path / "run")
    train.main(["--data", dataset, "--arch", "temc2", "--width", "0.0625", "--levels", "1", "--run", run,
                "--crop", "32", "--batch", "2", "--val-minutes", "0", "--threads", "1", "--max-steps", "3"])
    ck = torch.load(os.path.join(run, "checkpoint.pt"), weights_only=False)
    assert ck["state"]["skipped_steps"] == 1 and ck["state"]["step"] == 3
    assert all(torch.isfinite(v).all() for v in ck["model"].values() if v.is_floating_point())


def test_noise2noise_trains_on_the_reference_prefix(dataset, tmp_path):
    # --target-spp trains only on scenes with that prefix, against the prefix, with the
    # relative MSE; the checkpoint records the recipe for the model card.
    scenes = data.load_split(dataset, "train")
    with_prefix = [s for s in scenes if s.has_reference_prefix(2)]
    assert len(with_prefix) == 1 and not scenes[1].has_reference_prefix(2)
    assert [s.name for s in data.load_split(dataset, "train", 2)] == [with_prefix[0].name]
    target = data.make_sample(with_prefix[0], np.random.default_rng(0), 32, spp_index=0,
                              augment=False, aux_mode="full", origin=(0, 0), target_spp=2)[5]
    clean = data.make_sample(with_prefix[0], np.random.default_rng(0), 32, spp_index=0,
                             augment=False, aux_mode="full", origin=(0, 0))[5]
    assert not np.allclose(target, clean)
    run = str(tmp_path / "n2n")
    train.main(["--data", dataset, "--arch", "ae", "--width", "0.0625", "--run", run, "--crop", "32",
                "--batch", "2", "--val-minutes", "0", "--threads", "1", "--target-spp", "2",
                "--max-steps", "2", "--lr-half-life", "1"])
    ck = torch.load(os.path.join(run, "checkpoint.pt"), weights_only=False)
    hp = ck["state"]["hparams"]
    assert (hp["target_spp"], hp["loss"], hp["lr_half_life"]) == (2, "relmse", 1.0)
    assert ck["state"]["train_scenes"] == 1


def test_the_learning_rate_halves_with_training_time():
    class A:
        lr, lr_half_life, schedule = 1e-3, 2.0, "halflife"
    assert train.learning_rate(A, 0.0) == 1e-3
    assert abs(train.learning_rate(A, 2 * 3600.0) - 5e-4) < 1e-12
    assert train.learning_rate(A, 1e9) == 1e-3 * train.LR_FLOOR
    A.lr_half_life = 0.0
    assert train.learning_rate(A, 1e9) == 1e-3


def test_one_cycle_scales_with_the_global_batch_warms_up_and_anneals():
    class A:
        lr, schedule, batch, lr_batch, warmup = 1e-3, "onecycle", 64, 16, 0.1
        hours, cycle_hours, new_cycle = 1.0, 0.0, 0
    peak = 1e-3 * (64 * 4 / 16) ** 0.5  # four processes: a global batch of 256
    cycle = (500.0, 1000.0)  # a cycle begun at 500 s of a resumed run
    lr = lambda t: train.learning_rate(A, t, cycle, world=4)  # noqa: E731
    assert abs(lr(500.0) - peak / 25) < 1e-12 and abs(lr(600.0) - peak) < 1e-12
    assert lr(550.0) < lr(600.0) and lr(1050.0) < lr(800.0) < lr(600.0)
    assert abs(lr(1500.0) - peak * 1e-3) < 1e-12 and lr(9000.0) == lr(1500.0)
    # The cycle is kept in the state: it spans what is left of --hours, resumes keep it,
    # --new-cycle (or --cycle-hours with it) begins another.
    state = {}
    assert train.start_cycle(A, state, 600.0) == (600.0, 3000.0)
    assert train.start_cycle(A, state, 1200.0) == (600.0, 3000.0)
    A.new_cycle, A.cycle_hours = 1, 0.5
    assert train.start_cycle(A, state, 1200.0) == (1200.0, 1800.0) and state["cycle"] == [1200.0, 1800.0]


def test_a_checkpoint_without_recon_loads_alike_in_train_and_export(dataset, tmp_path):
    # models.RECON_DEFAULTS fills what a checkpoint's "recon" does not say, for resuming
    # (train.py) and exporting (export.py) alike: both read the same model from it.
    run = str(tmp_path / "run")
    args = ["--data", dataset, "--arch", "ae", "--width", "0.0625", "--run", run,
            "--crop", "32", "--batch", "2", "--val-minutes", "0", "--threads", "1"]
    train.main(args + ["--max-steps", "1"])
    path = os.path.join(run, "checkpoint.pt")
    ck = torch.load(path, weights_only=False)
    assert ck["recon"] == train.checkpoint_recon({})
    del ck["recon"]
    torch.save(ck, path)
    model, *_ = export.load_checkpoint(path)
    assert export.recon_of(model) == train.checkpoint_recon({})
    train.main(args + ["--max-steps", "2"])
    assert torch.load(path, weights_only=False)["state"]["step"] == 2
