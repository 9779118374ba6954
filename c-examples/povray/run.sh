#!/usr/bin/env bash
# POV-Ray host example, end to end: render scene.pov with few focal-blur and area-light
# samples to EXR (and a many-sample reference), denoise it colour-only with `temc denoise`,
# then check and picture the result.
#   c-examples/povray/run.sh [OUT_DIR] [MODEL.onnx]
# Needs Debian's povray package, `cargo build --release`, and the venv of scripts/test-all.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
out="$(realpath -m "${1:-$root/bench-out/povray}")"
model="${2:-}"
py="${TEMC_VENV:-$HOME/.cache/temc-venv}/bin/python"
mkdir -p "$out"
pov() { povray +I"$here/scene.pov" +W320 +H240 -D +FE "$@" > "$out/povray.log" 2>&1 || { tail -20 "$out/povray.log"; exit 1; }; }
pov +O"$out/noisy.exr" -A
pov +O"$out/reference.exr" -A Declare=Samples=256 Declare=Lights=8
model_args=(); [ -n "$model" ] && model_args=(--model "$model")
"$root/target/release/temc" denoise --color "$out/noisy.exr" -o "$out/denoised.exr" "${model_args[@]}"
"$py" "$here/../check_denoised.py" --noisy "$out/noisy.exr" --reference "$out/reference.exr" \
    --denoised "temc (colour only)=$out/denoised.exr" --png "$out/side-by-side.png" --require-better
echo "side by side (noisy, temc, reference): $out/side-by-side.png"
