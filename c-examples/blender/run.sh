#!/usr/bin/env bash
# Blender host example, end to end, headless: render a small Cycles scene at 16 samples
# (and a 512-sample reference), denoise it with temc twice as a post-pass (the `temc` CLI
# on the multi-layer EXR, and the C library loaded into Blender's Python with ctypes),
# then check and picture the result.
#   c-examples/blender/run.sh [OUT_DIR] [MODEL.onnx]
# Needs Debian's blender package, `cargo build --release`, and the venv of scripts/test-all.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
out="$(realpath -m "${1:-$root/bench-out/blender}")"
model="${2:-}"
py="${TEMC_VENV:-$HOME/.cache/temc-venv}/bin/python"
mkdir -p "$out"
bl() { blender -b --factory-startup -noaudio -P "$@" > "$out/blender.log" 2>&1 || { tail -20 "$out/blender.log"; exit 1; }; }
bl "$here/scene.py" -- "$out/noisy" 16
bl "$here/scene.py" -- "$out/reference" 512
model_args=(); [ -n "$model" ] && model_args=(--model "$model")
"$root/target/release/temc" denoise --color "$out/noisy/render.exr" -o "$out/temc-cli.exr" "${model_args[@]}"
bl "$here/host.py" -- "$out/noisy" "$root/target/release/libtemc.so" "$model"
grep "temc-blender" "$out/blender.log"
"$py" "$here/../check_denoised.py" --noisy "$out/noisy/render.exr" \
    --reference "$out/reference/render.exr" \
    --denoised "temc CLI=$out/temc-cli.exr" --denoised "temc via ctypes=$out/noisy/temc-ctypes.pfm" \
    --png "$out/side-by-side.png" --require-better
echo "side by side (noisy, temc CLI, temc via ctypes, reference): $out/side-by-side.png"
