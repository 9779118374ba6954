"""Turns one scene's Blender EXRs (family.py) into temc's data set layout (docs/render.md),
and writes the data set's manifest.json.

    python convert.py scene ROOT NAME      ROOT/test/NAME/raw/*.exr -> spp*.exr, ref.exr,
                                           scene.txt, done.json
    python convert.py manifest ROOT        ROOT/manifest.json from every test/*/done.json

Layers written: color.{R,G,B} (Combined), albedo.{R,G,B} (Denoising Albedo),
normal.{X,Y,Z} (the world-space Normal pass), depth.Z (Denoising Depth: distance along the
camera ray, 0 where the ray escaped), as read by training/temc_train/data.py `read_exr`.
Blender's world is Z-up; temc-render's is Y-up, so vectors map (x, y, z) -> (x, z, -y) (a
rotation), and scene.txt's camera line lets data.py turn normals into camera space.
"""

import json
import os
import sys

import numpy as np
import OpenEXR

# (temc layer, Blender pass, channels) in the order read_exr reads them.
PASSES = [("color", "Combined", "RGB"), ("albedo", "Denoising Albedo", "RGB"),
          ("normal", "Normal", "XYZ"), ("depth", "Denoising Depth", "Z")]
# Cycles writes a huge distance (about 1e10) where the camera ray escaped.
ESCAPED = 1e8


def z_up_to_y_up(v):
    """Blender (Z-up) vectors as temc-render's Y-up world: (x, y, z) -> (x, z, -y)."""
    v = np.asarray(v, np.float32)
    return np.stack([v[..., 0], v[..., 2], -v[..., 1]], -1)


def read_blender(path: str) -> dict:
    """Blender's multi-layer EXR as {pass.channel: [H, W] float32}."""
    with OpenEXR.File(path, separate_channels=True) as f:
        ch = f.channels()
        return {k.removeprefix("ViewLayer."): np.asarray(v.pixels, np.float32) for k, v in ch.items()}


def temc_layers(ch: dict) -> dict:
    """Blender passes -> temc channel arrays."""
    out = {}
    for layer, blender, names in PASSES:
        for c in names:
            out[f"{layer}.{c}"] = ch[f"{blender}.{c}"]
    n = z_up_to_y_up(np.stack([out.pop(f"normal.{c}") for c in "XYZ"], -1))
    out.update({f"normal.{c}": np.ascontiguousarray(n[..., i]) for i, c in enumerate("XYZ")})
    d = out["depth.Z"]
    out["depth.Z"] = np.where(np.isfinite(d) & (d < ESCAPED), d, 0).astype(np.float32)
    return out


def write_temc(path: str, layers: dict) -> None:
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    chans = {k: OpenEXR.Channel(k, np.ascontiguousarray(v, np.float32)) for k, v in layers.items()}
    tmp = path + ".tmp.exr"
    with OpenEXR.File(header, chans) as f:
        f.write(tmp)
    os.replace(tmp, path)


def scene_txt(cam: dict) -> str:
    """Not a temc-render scene: only its camera line, which data.py reads for the frame."""
    eye, tgt = z_up_to_y_up(cam["eye"]), z_up_to_y_up(cam["target"])
    f = lambda v: " ".join(f"{x:.6g}" for x in v)
    return (f"# Cycles scene '{cam['name']}' (scenes/cycles/family.py, Blender {cam['blender']}):\n"
            f"# {cam['about']}. Coordinates mapped to Y-up; temc-render cannot render it.\n"
            f"camera eye {f(eye)} target {f(tgt)}\n")


def convert_scene(root: str, name: str) -> dict:
    d = os.path.join(root, "test", name)
    raw = os.path.join(d, "raw")
    cam = json.load(open(os.path.join(d, "camera.json")))
    times = json.load(open(os.path.join(d, "timings.json")))
    spps = sorted(int(s) for s in times["noisy"])
    noisy = []
    for spp in spps:
        f = f"spp{spp:04d}.exr"
        write_temc(os.path.join(d, f), temc_layers(read_blender(os.path.join(raw, f))))
        noisy.append([spp, f])
    write_temc(os.path.join(d, "ref.exr"), temc_layers(read_blender(os.path.join(raw, "ref.exr"))))
    with open(os.path.join(d, "scene.txt"), "w") as f:
        f.write(scene_txt({**cam, "name": name}))
    record = {"name": name, "split": "test", "dir": f"test/{name}", "noisy": noisy,
              "reference": "ref.exr", "reference_prefixes": [],
              "seconds_noisy": sum(times["noisy"].values()),
              "seconds_reference": times["reference"],
              "features": f"cycles: {cam['about']}", "sampling": "cycles-independent-seeds"}
    with open(os.path.join(d, "done.json"), "w") as f:
        json.dump(record, f, indent=1)
    return record


def write_manifest(root: str, options: dict) -> None:
    t = os.path.join(root, "test")
    records = []
    for name in sorted(os.listdir(t)):
        p = os.path.join(t, name, "done.json")
        if os.path.exists(p):
            records.append(json.load(open(p)))
    m = {"options": options, "layers": [f"{l}.{c}" for l, _, cs in PASSES for c in cs],
         "scenes": records,
         "seconds_noisy": sum(r["seconds_noisy"] for r in records),
         "seconds_reference": sum(r["seconds_reference"] for r in records),
         "sampling": {"cycles-independent-seeds": len(records)}}
    tmp = os.path.join(root, "manifest.json.tmp")
    with open(tmp, "w") as f:
        json.dump(m, f, indent=1)
    os.replace(tmp, os.path.join(root, "manifest.json"))


def main(argv):
    if argv[0] == "scene":
        r = convert_scene(argv[1], argv[2])
        print(f"temc-cycles: {r['name']} converted ({len(r['noisy'])} noisy + reference)")
    elif argv[0] == "manifest":
        options = json.loads(argv[2]) if len(argv) > 2 else {}
        write_manifest(argv[1], {"renderer": "blender-cycles", **options})
    else:
        sys.exit(f"unknown command {argv[0]!r}; see the docstring")


if __name__ == "__main__":
    main(sys.argv[1:])
