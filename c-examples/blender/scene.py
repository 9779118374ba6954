"""Builds a small scene in Blender (no .blend file needed), renders it with Cycles on the
CPU into one multi-layer EXR with the passes temc reads (Noisy Image, Denoising Albedo,
Denoising Normal, Depth), and also writes those passes as single EXR files for the ctypes
host (host.py). Blender's own denoiser fills Combined when this build has OIDN.

    blender -b --factory-startup -P scene.py -- OUT_DIR SAMPLES [WIDTH HEIGHT]
"""

import os
import sys

import bpy

argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
out = os.path.abspath(argv[0] if argv else "out")
samples = int(argv[1]) if len(argv) > 1 else 16
width, height = (int(argv[2]), int(argv[3])) if len(argv) > 3 else (320, 240)
os.makedirs(out, exist_ok=True)

# An empty scene.
bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene


def material(name, rgb, rough=0.5, metal=0.0):
    m = bpy.data.materials.new(name)
    m.use_nodes = True
    bsdf = m.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*rgb, 1.0)
    bsdf.inputs["Roughness"].default_value = rough
    bsdf.inputs["Metallic"].default_value = metal
    return m


def add(obj, mat):
    obj.data.materials.append(mat)
    return obj


bpy.ops.mesh.primitive_plane_add(size=20)
add(bpy.context.object, material("floor", (0.6, 0.6, 0.6), 0.8))
bpy.ops.mesh.primitive_uv_sphere_add(radius=1, location=(-1.2, 0, 1), segments=48, ring_count=24)
bpy.ops.object.shade_smooth()
add(bpy.context.object, material("red", (0.7, 0.1, 0.08), 0.3))
bpy.ops.mesh.primitive_cube_add(size=1.6, location=(1.3, 0.6, 0.8), rotation=(0, 0, 0.5))
add(bpy.context.object, material("gold", (1.0, 0.76, 0.33), 0.25, 1.0))
bpy.ops.mesh.primitive_plane_add(size=30, location=(0, 6, 0), rotation=(1.5708, 0, 0))
add(bpy.context.object, material("wall", (0.3, 0.45, 0.7), 0.9))

# A small area light: soft shadows, so low sample counts are visibly noisy.
bpy.ops.object.light_add(type="AREA", location=(2.5, -2.5, 5))
light = bpy.context.object
light.data.energy = 800
light.data.size = 0.6
light.rotation_euler = (0.5, 0.4, 0)

bpy.ops.object.camera_add(location=(0, -7.5, 3.2), rotation=(1.2, 0, 0))
scene.camera = bpy.context.object
world = bpy.data.worlds.new("world")
world.use_nodes = True
world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.05
scene.world = world

scene.render.engine = "CYCLES"
scene.cycles.device = "CPU"
scene.cycles.samples = samples
scene.cycles.use_adaptive_sampling = False
scene.cycles.seed = 1
scene.render.resolution_x, scene.render.resolution_y = width, height
scene.render.resolution_percentage = 100
scene.render.threads_mode = "AUTO"
try:
    import _cycles
    has_oidn = bool(getattr(_cycles, "with_openimagedenoise", False))
except ImportError:
    has_oidn = False
scene.cycles.use_denoising = has_oidn  # Combined = Blender's own denoiser, when built in
view = scene.view_layers[0]
view.cycles.denoising_store_passes = True  # Noisy Image, Denoising Albedo, Denoising Normal
view.use_pass_z = True
scene.render.image_settings.file_format = "OPEN_EXR_MULTILAYER"
scene.render.image_settings.color_depth = "32"
scene.render.filepath = os.path.join(out, "render.exr")

# The compositor also writes the passes as single EXR files for the ctypes host.
scene.use_nodes = True
tree = scene.node_tree
tree.nodes.clear()
rl = tree.nodes.new("CompositorNodeRLayers")
comp = tree.nodes.new("CompositorNodeComposite")
tree.links.new(rl.outputs["Image"], comp.inputs["Image"])
fo = tree.nodes.new("CompositorNodeOutputFile")
fo.base_path = out
fo.format.file_format = "OPEN_EXR"
fo.format.color_depth = "32"
fo.file_slots.clear()
# Without Blender's denoiser, Combined ("Image") is the noisy render itself.
for slot, output in (("noisy", "Noisy Image" if has_oidn else "Image"), ("albedo", "Denoising Albedo"),
                     ("normal", "Denoising Normal")):
    fo.file_slots.new(slot)
    tree.links.new(rl.outputs[output], fo.inputs[slot])

bpy.ops.render.render(write_still=True)
print(f"temc-blender: rendered {width}x{height} at {samples} samples to {out} "
      f"(Blender denoiser: {'yes' if has_oidn else 'not in this build'})")
