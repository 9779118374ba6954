"""Shards (shard.py) and training from one (train.py --shard --device --minutes): the CPU
fallback of scripts/train-gpu, on test_data_train's tiny synthetic data set."""

import csv
import json
import os
import zipfile

import numpy as np
import pytest
import torch

from temc_train import data
from temc_train.drivers import export, shard, ship, train
from test_data_train import dataset  # noqa: F401  (the fixture)

TRAIN_ARGS = ["--arch", "ae", "--width", "0.0625", "--crop", "32", "--batch", "2",
              "--val-minutes", "0", "--threads", "1"]


@pytest.fixture(scope="module")
def packed(dataset, tmp_path_factory):  # noqa: F811
    out = str(tmp_path_factory.mktemp("shards") / "tiny.npz")
    m = shard.pack(dataset, out, max_mib=1, crop=16, crops_per_scene=3, val_mib=0.5, verbose=False)
    return out, m


@pytest.fixture(scope="module")
def whole(dataset, tmp_path_factory):  # noqa: F811
    """Whole 32x32 images: the loss's MS-SSIM needs crops of 32 at least."""
    out = str(tmp_path_factory.mktemp("shards") / "whole.npz")
    m = shard.pack(dataset, out, max_mib=1, crop=0, verbose=False)
    assert [r["shape"] for r in m["train"]] == [[32, 32]] * 2
    return out


def test_shard_holds_float16_arrays_and_a_manifest(dataset, packed):  # noqa: F811
    out, m = packed
    assert m["dataset"] == os.path.basename(dataset) and m["spp"] == [1, 4]
    assert len(m["train"]) == 6 and len(m["val"]) == 1 and m["clamped"] == {}
    with zipfile.ZipFile(out) as zf:
        assert json.loads(zf.read("manifest.json"))["train"] == m["train"]
    with np.load(out) as z:
        for k in shard.KEYS:
            assert z[f"train/00000/{k}"].dtype == np.float16
        assert z["train/00000/color"].shape == (2, 16, 16, 3)
        assert z["val/00000/reference"].shape == (32, 32, 3)  # smaller than the centre crop


def test_shard_scenes_match_the_data_set(dataset, packed):  # noqa: F811
    out, m = packed
    tr, va = shard.load(out)
    by_name = {s.name: s for s in data.load_split(dataset, "train") + data.load_split(dataset, "val")}
    for item, rec in zip(tr + va, m["train"] + m["val"]):
        src = by_name[rec["scene"]]
        (y, x), (h, w) = rec["origin"], rec["shape"]
        assert item.shape == (h, w) and item.spp == src.spp
        assert item.scale == src.scale and item.depth_scale == src.depth_scale
        for k in shard.KEYS:
            assert item.a[k].dtype == np.float32
            want = src.a[k][..., y:y + h, x:x + w, :] if src.a[k].ndim == 4 else (
                src.a[k][y:y + h, x:x + w] if k == "reference" else src.a[k][:, y:y + h, x:x + w])
            np.testing.assert_allclose(item.a[k], want, rtol=1e-3, atol=1e-4)
    xs = data.batch(tr, np.random.default_rng(0), 3, crop=16)
    assert [x.shape[1:] for x in xs] == [(2, 16, 16), (1, 16, 16), (7, 16, 16)] + [(3, 16, 16)] * 3
    assert len(data.validation_set(va, 16)[0]) == 2  # one val scene, two spp


def test_shard_stops_before_the_size_limit(dataset, packed, tmp_path):  # noqa: F811
    out, m = packed
    limit = (os.path.getsize(out) - 1) / 2**20
    small = str(tmp_path / "small.npz")
    m2 = shard.pack(dataset, small, max_mib=limit, crop=16, crops_per_scene=3, val_mib=0.5,
                    verbose=False)
    assert os.path.getsize(small) <= limit * 2**20
    assert 0 < len(m2["train"]) < len(m["train"])


def test_float16_overflow_is_clamped_and_counted():
    clamped = {}
    x = shard._f16(np.array([1.0, 1e6, -1e6, np.inf, np.nan], np.float32), clamped, "color")
    assert x.dtype == np.float16 and clamped == {"color": 2}
    assert x[1] == 65504 and x[2] == -65504 and np.isinf(x[3]) and np.isnan(x[4])


def test_training_from_a_shard_resumes_and_exports(dataset, whole, tmp_path):  # noqa: F811
    out = whole
    run = str(tmp_path / "run")
    args = ["--shard", out, "--device", "cpu", "--run", run] + TRAIN_ARGS
    train.main(args + ["--max-steps", "2"])
    ck_path = os.path.join(run, "checkpoint.pt")
    ck = torch.load(ck_path, map_location="cpu", weights_only=False)
    assert ck["state"]["step"] == 2 and ck["state"]["gpu_seconds"] == 0.0
    assert ck["state"]["train_s"] > 0 and ck["dataset"] == os.path.basename(dataset)
    train.main(args + ["--max-steps", "4"])
    # A spent --minutes budget runs no step; batches from a worker process run as well.
    train.main(args + ["--max-steps", "9", "--minutes", "0"])
    train.main(args + ["--max-steps", "5", "--workers", "1"])
    ck = torch.load(ck_path, map_location="cpu", weights_only=False)
    assert ck["state"]["step"] == 5 and ck["state"]["gpu_seconds"] == 0.0
    with open(os.path.join(run, "log.csv")) as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == train.LOG_COLUMNS
    assert [r["step"] for r in rows] == ["0", "1", "2", "3", "4", "5"]
    assert {r["device"] for r in rows} == {"cpu"}
    assert len(ship.read_log(run)) == len(rows)
    for path in (ck_path, os.path.join(run, "model.pt")):
        model, arch, width, info = export.load_checkpoint(path)
        assert (arch, width, info["train_steps"], info["dataset"]) == (
            "ae", 0.0625, 5, os.path.basename(dataset))


def test_an_old_log_gets_the_device_column(tmp_path):
    run = tmp_path / "old"
    run.mkdir()
    (run / "log.csv").write_text("step,train_seconds,train_loss,val_loss\n0,0.0,,0.5\n10,3.0,0.4,0.45\n")
    assert [r["val_loss"] for r in ship.read_log(str(run))] == ["0.5", "0.45"]  # readable as is
    log, w = train.open_log(str(run / "log.csv"))
    w.writerow([20, "6.0", "0.3", "0.4", "cuda"])
    log.close()
    with open(run / "log.csv") as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == train.LOG_COLUMNS
    assert [(r["step"], r["device"]) for r in rows] == [("0", "cpu"), ("10", "cpu"), ("20", "cuda")]
    assert [r["val_loss"] for r in ship.read_log(str(run))] == ["0.5", "0.45", "0.4"]


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")
def test_training_on_cuda_counts_gpu_seconds(whole, tmp_path):
    out = whole
    run = str(tmp_path / "gpu")
    args = ["--shard", out, "--run", run] + TRAIN_ARGS
    train.main(args + ["--device", "cuda", "--max-steps", "2"])
    ck = torch.load(os.path.join(run, "checkpoint.pt"), weights_only=False)  # CPU tensors
    assert all(t.device.type == "cpu" for t in ck["model"].values())
    assert ck["state"]["gpu_seconds"] > 0 and ck["state"]["train_s"] == 0.0
    train.main(args + ["--device", "cpu", "--max-steps", "3"])  # resumes on the CPU
    ck = torch.load(os.path.join(run, "checkpoint.pt"), weights_only=False)
    assert ck["state"]["step"] == 3 and ck["state"]["train_s"] > 0
