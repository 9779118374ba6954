"""scripts/train-gpu's CPU fallback end to end, and training under torchrun with two gloo
processes (DistributedDataParallel on the CPU), on test_shard's tiny shard."""

import csv
import json
import os
import shutil
import subprocess
import sys
import time

import torch

from temc_train import data
from temc_train.drivers import export, train
from test_data_train import dataset  # noqa: F401  (the fixture)
from test_shard import whole  # noqa: F401  (the fixture)

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
TINY = ["--arch", "ae", "--width", "0.0625", "--crop", "32", "--batch", "2", "--threads", "1"]


def run(cmd, **env):
    p = subprocess.run(cmd, cwd=os.path.join(ROOT, "training"), capture_output=True, text=True,
                       env={**os.environ, "CUDA_VISIBLE_DEVICES": "", **env}, timeout=600)
    assert p.returncode == 0, p.stdout[-3000:] + p.stderr[-3000:]
    return p.stdout


def steps(folder):
    return torch.load(os.path.join(folder, "checkpoint.pt"), weights_only=False)["state"]


def test_the_gpu_command_falls_back_to_the_cpu_and_resumes(whole, tmp_path):  # noqa: F811
    out = str(tmp_path / "out")
    cmd = [os.path.join(ROOT, "scripts", "train-gpu"), whole, out, "5", "--width", "0.0625",
           "--crop", "32", "--batch", "2", "--max-steps", "2"]
    venv = {"TEMC_VENV": sys.prefix}
    text = run(cmd, **venv)
    assert "training on 0 GPU(s)" in text and "exported" in text
    assert sorted(os.listdir(out)) == ["checkpoint.pt", "log.csv", "model.onnx", "train.out"]
    assert all(os.path.getsize(os.path.join(out, f)) <= 16 << 20 for f in os.listdir(out))
    st = steps(out)
    assert st["step"] == 2 and st["train_s"] > 0 and st["gpu_seconds"] == 0.0
    assert (st["hparams"]["sampler"], st["hparams"]["schedule"], st["hparams"]["processes"]) == ("device", "onecycle", 1)
    assert st["throughput"]["crops_per_s"] > 0 and st["throughput"]["steps"] == 2
    model, arch, width, info = export.load_checkpoint(os.path.join(out, "checkpoint.pt"))
    assert (arch, width, info["train_steps"]) == ("temc2", 0.0625, 2)
    run(cmd[:-1] + ["4"], **venv)  # the same command resumes
    assert steps(out)["step"] == 4
    with open(os.path.join(out, "log.csv")) as f:
        assert [r["step"] for r in csv.DictReader(f)] == ["0", "2", "4"]  # validated at each end


def test_two_gloo_processes_train_one_model_that_resumes_alone(whole, tmp_path):  # noqa: F811
    runs = str(tmp_path / "ddp")
    args = ["--shard", whole, "--run-dir", runs, "--device", "cpu", "--sampler", "device",
            "--val-minutes", "0", "--amp", "bf16", "--channels-last", "1", "--schedule", "onecycle",
            "--lr-batch", "2"] + TINY
    run([sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc-per-node", "2",
         "-m", "temc_train.drivers.train"] + args + ["--max-steps", "3"], OMP_NUM_THREADS="1")
    st = steps(runs)
    assert st["step"] == 3 and st["hparams"]["processes"] == 2 and st["hparams"]["amp"] == "bf16"
    with open(os.path.join(runs, "log.csv")) as f:
        rows = list(csv.DictReader(f))
    assert [r["step"] for r in rows] == ["0", "1", "2", "3"]  # one writer: rank 0
    assert all(float(r["val_loss"]) > 0 for r in rows)
    train.main(args + ["--max-steps", "4"])  # one process takes the run over
    assert steps(runs)["step"] == 4


def test_the_device_sampler_trains_from_a_data_set_folder(dataset, tmp_path):  # noqa: F811
    runs = str(tmp_path / "folder")
    train.main(["--data", dataset, "--run", runs, "--sampler", "device", "--val-minutes", "0",
                "--max-steps", "2"] + TINY)
    st = steps(runs)
    assert st["step"] == 2 and st["hparams"]["sampler"] == "device" and st["train_scenes"] == 2


RENDERER = os.path.join(ROOT, "target", "gpu", "temc-render")


def test_the_gpu_command_trains_on_scenes_it_renders_as_it_trains(tmp_path):
    """With the lean renderer the GPU machine gets (scripts/build-render-gpu, which
    scripts/test-all runs first), at a tiny size."""
    assert os.path.exists(RENDERER), f"{RENDERER}: run scripts/build-render-gpu first (scripts/test-all does)"
    out = str(tmp_path / "out")
    text = run([os.path.join(ROOT, "scripts", "train-gpu"), RENDERER, out, "5", "--arch", "ae",
                "--width", "0.0625", "--crop", "32", "--batch", "2", "--max-steps", "2"],
               TEMC_VENV=sys.prefix, TEMC_GPU_DATA=str(tmp_path / "scenes"),
               TEMC_GPU_RENDER="--size 32 --spp 1,4 --ref-spp 8", TEMC_GPU_FIRST="2 1")
    assert "rendering scenes from index" in text
    assert sorted(os.listdir(out)) == ["checkpoint.pt", "log.csv", "model.onnx", "render.log", "train.out"]
    st = steps(out)
    assert st["step"] == 2 and st["session_scenes"] >= 2
    # Scenes past the committed data set's 1000: never one of its test scenes.
    with open(tmp_path / "scenes" / "manifest.json") as f:
        names = [r["name"] for r in json.load(f)["scenes"]]
    assert names and all(n.startswith("scene-") and int(n[6:]) >= 1000 for n in names)


def test_scenes_that_land_are_read_in_worker_processes(dataset, tmp_path):  # noqa: F811
    root = tmp_path / "ds"
    shutil.copytree(dataset, root)
    with open(root / "manifest.json") as f:
        m = json.load(f)
    full = list(m["scenes"])
    (root / "manifest.json").write_text(json.dumps({**m, "scenes": [r for r in full if r["name"] != "scene-00001"]}))
    loader = data.SceneLoader(str(root), "train", ["scene-00000"])
    try:
        assert loader.poll() == []  # nothing new yet
        (root / "manifest.json").write_text(json.dumps({**m, "scenes": full}))
        got, deadline = [], time.monotonic() + 120
        while not got and time.monotonic() < deadline:
            got = loader.poll()
            time.sleep(0.1)
        assert [s.name for s in got] == ["scene-00001"] and got[0].a["color"].shape[0] == 2
        assert loader.poll() == []  # each scene once
    finally:
        loader.close()
