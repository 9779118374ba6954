"""What a Noise2Noise target saves in rendering: the data set's recorded render seconds per
scene, noisy inputs against the clean reference against a reference prefix (a prefix of
`p` spp costs p / ref_spp of the reference render, which is progressive).

    python -m temc_train.probes.n2n_cost --data ../data/spectral-v2 --prefix-spp 64

Prints one paragraph (Markdown) for docs/noise2noise.md.
"""

import argparse
import json
import os


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", required=True)
    ap.add_argument("--prefix-spp", type=int, required=True)
    a = ap.parse_args(argv)
    with open(os.path.join(a.data, "manifest.json")) as f:
        m = json.load(f)
    rows = [r for r in m["scenes"] if r["split"] == "train"]
    ref_spp = m["options"]["ref_spp"]
    noisy = sum(r["seconds_noisy"] for r in rows) / len(rows)
    ref = sum(r["seconds_reference"] for r in rows) / len(rows)
    prefix = ref * a.prefix_spp / ref_spp
    clean_scene, n2n_scene = noisy + ref, noisy + prefix
    print(f"Rendering cost per training scene ({len(rows)} scenes, wall seconds as the data set "
          f"recorded them; the thread count varied between sessions, the ratios hold): noisy inputs {noisy:.1f} s, the {ref_spp}-spp reference {ref:.1f} s, a "
          f"{a.prefix_spp}-spp prefix {prefix:.1f} s. A scene with a clean reference costs "
          f"{clean_scene:.1f} s, one with a Noise2Noise target {n2n_scene:.1f} s: "
          f"{clean_scene / n2n_scene:.2f}x as many scenes per render CPU-hour. (The data set "
          f"writes both, so the runs above train on the same scenes.)")


if __name__ == "__main__":
    main()
