import glob
import math
import os

import numpy as np
import onnx
import pytest
import torch

from temc_train import receptive
from temc_train.drivers import export
from temc_train.models import ARCHS, build, checkpoint_recon


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    d = tmp_path_factory.mktemp("onnx")
    out = {}
    for arch in ARCHS:
        torch.manual_seed(0)
        m = build(arch, 0.0625)
        export.randomize_untrained(m, 0)
        path = str(d / f"{arch}.onnx")
        diff = export.export(m, path, export.metadata(arch, 0.0625, export.recon_of(m)))
        out[arch] = (m.eval(), path, diff)
    return out


@pytest.mark.parametrize("arch", ARCHS)
def test_onnxruntime_matches_pytorch(exported, arch):
    _, _, diff = exported[arch]
    assert diff <= export.PARITY_TOL


@pytest.mark.parametrize("arch", ARCHS)
def test_metadata_and_opset(exported, arch):
    _, path, _ = exported[arch]
    m = onnx.load(path)
    meta = {p.key: p.value for p in m.metadata_props}
    for key in ["temc.format", "temc.architecture", "temc.width", "temc.alignment",
                "temc.receptive_field", "temc.tile_overlap", "temc.chroma_encoding",
                "temc.aux_layout", "temc.pq_nits_per_unit", "temc.dataset",
                "temc.train_steps", "temc.test_relmse", "temc.levels", "temc.kernel",
                "temc.demodulate", "temc.demod_eps"]:
        assert key in meta, key
    assert meta["temc.architecture"] == arch
    assert meta["temc.dataset"] == "none"
    assert int(meta["temc.tile_overlap"]) % 32 == 0
    assert int(meta["temc.tile_overlap"]) * 2 >= int(meta["temc.receptive_field"])
    assert meta["temc.format"] == "2" and meta["temc.levels"] == "3" and meta["temc.kernel"] == "5"
    assert max(o.version for o in m.opset_import if o.domain in ("", "ai.onnx")) >= 17
    assert [i.name for i in m.graph.input] == ["chroma", "luma", "aux"]
    assert [o.name for o in m.graph.output] == ["filters0", "filters1", "filters2"]


@pytest.mark.parametrize("arch", ARCHS)
def test_symbolic_size_runs_at_two_sizes(exported, arch):
    model, path, _ = exported[arch]
    # Neither size is the export's 64x64; the batch axis is symbolic too.
    for n, h, w in [(1, 32, 64), (2, 96, 32)]:
        xs = export.example_inputs(h, w, seed=h, batch=n)
        got = export.run_ort(path, xs)
        with torch.no_grad():
            want = [f.numpy() for f in model(*xs)]
        assert [g.shape for g in got] == [(n, 52, h >> l, w >> l) for l in range(3)]
        assert export.max_diff(got, want) <= export.PARITY_TOL


def test_command_line_exports_a_checkpoint(tmp_path, monkeypatch):
    torch.manual_seed(3)
    m = build("ae", 0.0625)
    ckpt = tmp_path / "ae.pt"
    torch.save({"model": m.state_dict(), "arch": "ae", "width": 0.0625,
                "dataset": "toy", "train_steps": 12,
                "recon": {"levels": 3, "kernel": 5, "split": "both", "demodulate": True,
                          "eps": 0.02}}, ckpt)
    out = tmp_path / "ae.onnx"
    monkeypatch.setattr("sys.argv", ["export", "--checkpoint", str(ckpt), "--out", str(out),
                                     "--test-relmse", "0.5"])
    export.main()
    meta = {p.key: p.value for p in onnx.load(out).metadata_props}
    assert (meta["temc.architecture"], meta["temc.width"]) == ("ae", "0.0625")
    assert (meta["temc.dataset"], meta["temc.train_steps"], meta["temc.test_relmse"]) == \
        ("toy", "12", "0.5")
    assert (meta["temc.demodulate"], meta["temc.demod_eps"]) == ("1", "0.02")
    assert meta["temc.upsample"] == "nearest"  # what the model trained with
    xs = export.example_inputs(32, 32, seed=9)
    with torch.no_grad():
        want = [f.numpy() for f in m.eval()(*xs)]
    assert export.max_diff(export.run_ort(str(out), xs), want) <= export.PARITY_TOL
    # --upsample exports the other composition, the network unchanged.
    monkeypatch.setattr("sys.argv", ["export", "--checkpoint", str(ckpt), "--out", str(out),
                                     "--upsample", "bilinear"])
    export.main()
    meta = {p.key: p.value for p in onnx.load(out).metadata_props}
    assert meta["temc.upsample"] == "bilinear" and meta["temc.levels"] == "3"
    assert export.max_diff(export.run_ort(str(out), xs), want) <= export.PARITY_TOL
    # A bare state_dict needs the architecture and width on the command line.
    torch.save(m.state_dict(), ckpt)
    with pytest.raises(ValueError):
        export.load_checkpoint(str(ckpt))
    assert export.load_checkpoint(str(ckpt), "ae", 0.0625)[1:3] == ("ae", 0.0625)


def test_fused_variant_is_the_same_function(tmp_path):
    torch.manual_seed(0)
    m = build("temc2", 0.0625)
    export.randomize_untrained(m, 1)
    path = str(tmp_path / "f.onnx")
    export.export(m, path, export.metadata("temc2", 0.0625, export.recon_of(m)), variant="fused")
    ops = {n.op_type for n in onnx.load(path).graph.node}
    assert "BatchNormalization" not in ops
    xs = export.example_inputs(64, 64, seed=5)
    with torch.no_grad():
        want = [f.numpy() for f in m.eval()(*xs)]
    assert export.max_diff(export.run_ort(path, xs), want) <= export.PARITY_TOL
    # The caller's model is untouched by the folds.
    with torch.no_grad():
        assert all(np.array_equal(f.numpy(), w) for f, w in zip(m(*xs), want))


def test_receptive_fields():
    # Measured values; they change only if an architecture does. The autoencoder's
    # footprint depends on the pixel's phase in the pooling grid (192 px for a pixel aligned
    # to 32, 224 elsewhere); the worst case is kept. TEMC-2's extra stabilising conv at 1/32
    # resolution widens DEMC's by 2 x 32 px.
    rf = {a: receptive.receptive_field(a) for a in ARCHS}
    assert rf == {"ae": 224, "demc": 340, "temc1": 340, "temc2": 404}, rf
    for a in ARCHS:
        overlap = receptive.tile_overlap(a, 3, 5)
        assert overlap % 32 == 0
        # Half the network's RF plus the reconstruction's reach (17 px) and block (4 px).
        assert overlap >= max(math.ceil(rf[a] / 2), receptive.measure(a).reach) + 17 + 4
        assert overlap - 32 < max(math.ceil(rf[a] / 2), receptive.measure(a).reach) + 21


@pytest.mark.parametrize("arch", ["ae", "temc2"])
def test_random_network_footprint_lies_inside_the_receptive_field(arch):
    # Plain backprop through a random network (the naive measurement) never sees more than
    # the linearised one: the linearisation loses no path.
    torch.manual_seed(0)
    m = build(arch, receptive.WIDTH).eval()
    export.randomize_untrained(m, 0)  # a fresh head is zero: no gradient at all
    size = 448
    xs = [x.requires_grad_() for x in export.example_inputs(size, size, seed=1)]
    m(*xs)[0][0, :, size // 2, size // 2].sum().backward()
    hit = sum((x.grad[0] != 0).any(dim=0) for x in xs).bool()
    rows, cols = hit.any(dim=1).nonzero(), hit.any(dim=0).nonzero()
    assert rows.min() > 0 and rows.max() < size - 1
    extent = int(max(rows.max() - rows.min(), cols.max() - cols.min())) + 1
    assert 0.5 * receptive.receptive_field(arch) < extent <= receptive.receptive_field(arch)


def test_committed_goldens_are_onnxruntime_outputs():
    # The Rust parity test trusts tests/data/golden: check that each filtersL.npy is what
    # onnxruntime computes today from the committed model and inputs.
    import pathlib

    root = pathlib.Path(__file__).resolve().parents[2] / "tests" / "data"
    for arch in ARCHS:
        name = f"{arch}_w{export.GOLDEN_WIDTH}"
        g = root / "golden" / name
        xs = [torch.from_numpy(np.load(g / f"{n}.npy")) for n in export.INPUTS]
        got = export.run_ort(str(root / "models" / f"{name}.onnx"), xs)
        want = [np.load(g / f"filters{l}.npy") for l in range(len(got))]
        assert export.max_diff(got, want) <= 1e-6, name


RUNS = os.path.join(os.path.dirname(__file__), "..", "runs")


@pytest.mark.parametrize("run", sorted(glob.glob(os.path.join(RUNS, "*", "checkpoint.pt"))),
                         ids=lambda p: os.path.basename(os.path.dirname(p)))
def test_committed_checkpoints_load_with_their_recon(run):
    # Every committed run, those from before guides (no "guide" in "recon") included,
    # loads strictly into the model models.checkpoint_recon says it was trained as.
    raw = torch.load(run, map_location="cpu", weights_only=False)
    model, arch, width, _ = export.load_checkpoint(run)
    assert (arch, width) == (raw["arch"], raw["width"])
    assert export.recon_of(model) == checkpoint_recon(raw)
    assert checkpoint_recon(raw)["guide"] == raw["recon"].get("guide", False)
