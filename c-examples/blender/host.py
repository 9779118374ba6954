"""temc's C ABI in a real host: inside Blender's Python, load libtemc with ctypes, feed it
the passes that scene.py wrote (noisy colour, albedo, normal) and write the denoised image.

    blender -b --factory-startup -P host.py -- OUT_DIR LIBTEMC.so MODEL.onnx

Writes OUT_DIR/temc-ctypes.pfm. Blender keeps image rows bottom-up, which is also PFM's
order, and the denoiser does not care which way up the rows come, so no flip is needed.
Blender's pixels are RGBA floats: the images are passed with a 16-byte pixel stride, so
nothing is copied (and no numpy is needed: Debian's Blender runs without it).
"""

import array
import ctypes
import os
import sys

import bpy

out, lib_path, model = sys.argv[sys.argv.index("--") + 1:][:3]

TEMC_DEVICE_TYPE_DEFAULT = 0
TEMC_FORMAT_FLOAT3 = 3
TEMC_ERROR_NONE = 0

lib = ctypes.CDLL(lib_path)
vp, sz, cp = ctypes.c_void_p, ctypes.c_size_t, ctypes.c_char_p
for name, res, args in (
    ("temcNewDevice", vp, [ctypes.c_uint32]),
    ("temcCommitDevice", None, [vp]),
    ("temcGetDeviceError", ctypes.c_uint32, [vp, ctypes.POINTER(cp)]),
    ("temcNewFilter", vp, [vp, cp]),
    ("temcSetSharedFilterData", None, [vp, cp, vp, sz]),
    ("temcSetSharedFilterImage", None, [vp, cp, vp, ctypes.c_uint32, sz, sz, sz, sz, sz]),
    ("temcCommitFilter", None, [vp]),
    ("temcExecuteFilter", None, [vp]),
    ("temcReleaseFilter", None, [vp]),
    ("temcReleaseDevice", None, [vp]),
):
    f = getattr(lib, name)
    f.restype, f.argtypes = res, args


def check(device, what):
    msg = cp()
    err = lib.temcGetDeviceError(device, ctypes.byref(msg))
    if err != TEMC_ERROR_NONE:
        raise SystemExit(f"temc error {err} during {what}: {msg.value.decode() if msg.value else ''}")


def load(name):
    img = bpy.data.images.load(os.path.join(out, f"{name}0001.exr"))
    img.colorspace_settings.name = "Non-Color"  # raw values, no view transform
    w, h = img.size
    px = array.array("f", bytes(4 * w * h * 4))
    img.pixels.foreach_get(px)
    return px, w, h


def address(a):
    return a.buffer_info()[0]


color, w, h = load("noisy")
albedo, _, _ = load("albedo")
normal, _, _ = load("normal")
output = array.array("f", bytes(4 * w * h * 4))
weights = open(model, "rb").read() if model else None

device = lib.temcNewDevice(TEMC_DEVICE_TYPE_DEFAULT)
lib.temcCommitDevice(device)
check(device, "device commit")
filt = lib.temcNewFilter(device, b"TEMC2")
check(device, "filter creation")
if weights:
    buf = ctypes.create_string_buffer(weights, len(weights))
    lib.temcSetSharedFilterData(filt, b"weights", ctypes.cast(buf, vp), len(weights))
# else the library's built-in TEMC-2 (balanced quality, the default)
for name, arr in ((b"color", color), (b"albedo", albedo), (b"normal", normal), (b"output", output)):
    # RGB read from RGBA pixels: pixel stride 16 bytes, rows packed.
    lib.temcSetSharedFilterImage(filt, name, address(arr), TEMC_FORMAT_FLOAT3, w, h, 0, 16, 0)
lib.temcCommitFilter(filt)
check(device, "filter commit")
lib.temcExecuteFilter(filt)
check(device, "filter execute")
lib.temcReleaseFilter(filt)
lib.temcReleaseDevice(device)

path = os.path.join(out, "temc-ctypes.pfm")
with open(path + ".tmp", "wb") as f:
    f.write(f"PF\n{w} {h}\n-1.0\n".encode())
    rgb = array.array("f")
    for i in range(w * h):
        rgb.extend(output[4 * i:4 * i + 3])
    if sys.byteorder != "little":
        rgb.byteswap()
    f.write(rgb.tobytes())
os.replace(path + ".tmp", path)
print(f"temc-blender: denoised {w}x{h} through the C ABI -> {path}")
