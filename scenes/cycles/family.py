"""The Cycles test family: procedural scenes built in Blender's Python (no assets), each
rendered at several noisy spp and once as a reference, as Blender multi-layer EXRs.

    blender -b --factory-startup -noaudio -P family.py -- OUT NAME SIZE SPP,SPP,... REF_SPP

writes OUT/raw/spp0001.exr ... and OUT/raw/ref.exr (Combined, Denoising Albedo, Normal,
Depth), OUT/camera.json (eye and target, for the camera line of scene.txt) and
OUT/timings.json. `convert.py` turns them into the layers temc's data set reads.
`--list` after `--` prints the scene names.

Blender is Z-up; convert.py maps to temc-render's Y-up world.
"""

import json
import math
import os
import sys
import time
import zlib

import bpy
from mathutils import Vector


# ---- building blocks ---------------------------------------------------------------

def material(name, rgb, rough=0.5, metal=0.0, transmission=0.0, ior=1.45):
    m = bpy.data.materials.new(name)
    m.use_nodes = True
    b = m.node_tree.nodes["Principled BSDF"]
    b.inputs["Base Color"].default_value = (*rgb, 1.0)
    b.inputs["Roughness"].default_value = rough
    b.inputs["Metallic"].default_value = metal
    b.inputs["Transmission"].default_value = transmission
    b.inputs["IOR"].default_value = ior
    return m


def shader(name, node, output, **inputs):
    """A material of one shader node (`node`, e.g. "ShaderNodeEmission") whose `output`
    socket is the surface; `inputs` maps socket names to values."""
    m = bpy.data.materials.new(name)
    m.use_nodes = True
    nt = m.node_tree
    nt.nodes.clear()
    n = nt.nodes.new(node)
    for socket, value in inputs.items():
        n.inputs[socket].default_value = value
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    nt.links.new(n.outputs[output], out.inputs["Surface"])
    return m


def emissive(name, rgb, strength):
    return shader(name, "ShaderNodeEmission", "Emission", Color=(*rgb, 1.0), Strength=strength)


def glass(name, rgb=(1, 1, 1), rough=0.0, ior=1.5):
    return shader(name, "ShaderNodeBsdfGlass", "BSDF", Color=(*rgb, 1.0), Roughness=rough, IOR=ior)


def give(mat):
    """Assigns `mat` to the object just added and returns it."""
    obj = bpy.context.object
    obj.data.materials.append(mat)
    return obj


def box(loc, size, mat, rot=0.0):
    bpy.ops.mesh.primitive_cube_add(size=1, location=loc, rotation=(0, 0, rot))
    bpy.context.object.scale = size
    return give(mat)


def sphere(loc, r, mat):
    bpy.ops.mesh.primitive_uv_sphere_add(radius=r, location=loc, segments=48, ring_count=24)
    bpy.ops.object.shade_smooth()
    return give(mat)


def cylinder(loc, r, h, mat):
    bpy.ops.mesh.primitive_cylinder_add(radius=r, depth=h, location=loc, vertices=48)
    bpy.ops.object.shade_smooth()
    return give(mat)


def torus(loc, major, minor, mat, rot=(0, 0, 0)):
    bpy.ops.mesh.primitive_torus_add(location=loc, rotation=rot, major_radius=major,
                                     minor_radius=minor)
    bpy.ops.object.shade_smooth()
    return give(mat)


def plane(loc, size, mat, rot=(0, 0, 0)):
    bpy.ops.mesh.primitive_plane_add(size=size, location=loc, rotation=rot)
    return give(mat)


def room(w, d, h, mat, skip=()):
    """A closed box room, floor at z=0, walls as thin boxes (so light cannot leak through
    coplanar edges). `skip` leaves walls out: 'front' (-y), 'back', 'left', 'right', 'ceiling'."""
    t = 0.1
    parts = {"floor": ((0, 0, -t / 2), (w, d, t)), "ceiling": ((0, 0, h + t / 2), (w, d, t)),
             "back": ((0, d / 2 + t / 2, h / 2), (w, t, h)),
             "front": ((0, -d / 2 - t / 2, h / 2), (w, t, h)),
             "left": ((-w / 2 - t / 2, 0, h / 2), (t, d, h)),
             "right": ((w / 2 + t / 2, 0, h / 2), (t, d, h))}
    for name, (loc, size) in parts.items():
        if name not in skip:
            box(loc, size, mat)


def lamp(kind, loc, energy, size=0.1, rgb=(1, 1, 1), rot=(0, 0, 0), angle=None):
    bpy.ops.object.light_add(type=kind, location=loc, rotation=rot)
    light = bpy.context.object.data
    light.energy = energy
    light.color = rgb
    if kind == "AREA":
        light.size = size
    elif kind in ("POINT", "SPOT"):
        light.shadow_soft_size = size
    if kind == "SPOT" and angle:
        light.spot_size = angle
    if kind == "SUN":
        light.angle = math.radians(size)
    return bpy.context.object


def world(strength=0.0, rgb=(0.05, 0.05, 0.05), sky=None):
    """A flat background, or with `sky=(sun_elevation_deg, sun_rotation_deg)` a Nishita sky
    (Cycles' physical sky, procedural) whose disc is the sun."""
    w = bpy.data.worlds.new("world")
    w.use_nodes = True
    nt = w.node_tree
    bg = nt.nodes["Background"]
    if sky:
        s = nt.nodes.new("ShaderNodeTexSky")
        s.sky_type = "NISHITA"
        s.sun_elevation = math.radians(sky[0])
        s.sun_rotation = math.radians(sky[1])
        s.sun_disc = True
        nt.links.new(s.outputs["Color"], bg.inputs["Color"])
        bg.inputs["Strength"].default_value = strength or 0.3
    else:
        bg.inputs["Color"].default_value = (*rgb, 1.0)
        bg.inputs["Strength"].default_value = strength
    bpy.context.scene.world = w


def camera(eye, target, lens=35):
    bpy.ops.object.camera_add(location=eye)
    cam = bpy.context.object
    cam.data.lens = lens
    # No roll: up stays world +Z, as temc-render's camera keeps its world up.
    cam.rotation_euler = (Vector(target) - Vector(eye)).to_track_quat("-Z", "Y").to_euler()
    bpy.context.scene.camera = cam
    return {"eye": list(eye), "target": list(target), "lens_mm": lens}


# ---- the scenes ---------------------------------------------------------------------
# Each returns the camera record and a one-line description of what it tests.

def sun_sky_courtyard():
    world(sky=(35, 40), strength=0.25)
    plane((0, 0, 0), 30, material("stone", (0.55, 0.5, 0.45), 0.8))
    box((-1.5, 1, 1), (1.2, 1.2, 2), material("plaster", (0.8, 0.75, 0.7), 0.9), 0.3)
    box((1.4, 0.3, 0.5), (1, 1, 1), material("brick", (0.6, 0.25, 0.15), 0.7), -0.4)
    cylinder((0.2, 2.5, 1.5), 0.3, 3, material("column", (0.85, 0.85, 0.8), 0.6))
    return camera((0, -7, 2.5), (0, 0.5, 0.8)), "sun and Nishita sky outdoors, hard shadows"


def sun_sky_low():
    world(sky=(6, 200), strength=0.3)
    plane((0, 0, 0), 40, material("grass", (0.2, 0.35, 0.1), 0.9))
    for i in range(5):
        sphere((-3 + 1.5 * i, 0.5 * (i % 2), 0.5), 0.5, material(f"ball{i}", (0.7, 0.6 - 0.1 * i, 0.3 + 0.1 * i), 0.4))
    return camera((0, -8, 1.6), (0, 0, 0.5)), "low sun at dusk, long shadows, bright horizon"


def sun_through_pergola():
    world(sky=(50, 120), strength=0.25)
    plane((0, 0, 0), 30, material("deck", (0.5, 0.35, 0.2), 0.7))
    wood = material("slat", (0.6, 0.45, 0.3), 0.8)
    for i in range(7):
        box((-3 + i, 0, 2.5), (0.15, 5, 0.2), wood)
    for x in (-3.2, 3.2):
        for y in (-2.3, 2.3):
            box((x, y, 1.25), (0.2, 0.2, 2.5), wood)
    sphere((0.5, 0, 0.6), 0.6, material("white", (0.8, 0.8, 0.8), 0.5))
    return camera((0, -7, 1.7), (0, 0, 0.8)), "sun striped by slats, sky fill"


def small_lamps_room():
    world()
    room(6, 6, 3, material("walls", (0.7, 0.7, 0.65), 0.9))
    lamp("POINT", (-1.5, 1, 2.5), 60, 0.03, (1, 0.8, 0.6))
    lamp("POINT", (1.8, -0.5, 0.6), 25, 0.03, (0.6, 0.7, 1))
    box((0, 1, 0.4), (2, 1, 0.8), material("table", (0.4, 0.25, 0.15), 0.5))
    sphere((0.3, 1, 1.1), 0.3, material("vase", (0.2, 0.4, 0.6), 0.2))
    return camera((0, -2.8, 1.6), (0, 1, 0.8), 24), "a closed room lit by two tiny point lamps"


def spot_dark_stage():
    world()
    room(8, 8, 4, material("black", (0.08, 0.08, 0.08), 0.9))
    lamp("SPOT", (0, 0.8, 3.8), 1500, 0.02, (1, 0.9, 0.8), angle=math.radians(45))
    sphere((0, 1, 0.7), 0.7, material("orange", (0.8, 0.35, 0.1), 0.35))
    box((-1.5, 1.8, 0.5), (1, 1, 1), material("grey", (0.5, 0.5, 0.5), 0.6), 0.5)
    return camera((0, -3.5, 1.6), (0, 1, 0.6), 28), "one small spot lamp in a dark room, mostly black"


def emissive_strips():
    world()
    room(6, 6, 3, material("walls", (0.6, 0.6, 0.6), 0.8))
    glow = emissive("strip", (1, 0.9, 0.75), 12)
    box((-2.9, 0, 2.8), (0.05, 5, 0.05), glow)
    box((2.9, 0, 2.8), (0.05, 5, 0.05), glow)
    box((0, 2.9, 0.1), (5, 0.05, 0.05), emissive("cove", (0.3, 0.5, 1), 20))
    cylinder((0, 0.8, 0.5), 0.5, 1, material("plinth", (0.75, 0.75, 0.75), 0.4))
    return camera((0, -2.8, 1.5), (0, 1, 0.7), 24), "only emissive mesh strips light the room"


def neon_sign():
    world()
    room(6, 6, 3, material("concrete", (0.35, 0.35, 0.33), 0.85), skip=("front",))
    torus((0, 2.9, 1.6), 0.6, 0.04, emissive("neon-pink", (1, 0.2, 0.6), 40), (math.pi / 2, 0, 0))
    torus((1.2, 2.9, 1.9), 0.3, 0.04, emissive("neon-cyan", (0.2, 0.9, 1), 40), (math.pi / 2, 0, 0))
    sphere((0, 1, 0.5), 0.5, material("satin", (0.7, 0.7, 0.7), 0.25))
    return camera((0, -3.5, 1.4), (0, 2, 1.2), 28), "thin emissive tori (neon) are the only light"


def glass_caustic():
    world()
    room(6, 6, 3, material("white", (0.75, 0.75, 0.75), 0.9))
    lamp("AREA", (1, -0.5, 2.9), 150, 0.25, rot=(0, 0, 0))
    sphere((0, 0.8, 0.6), 0.6, glass("glass"))
    box((-1.3, 1.2, 0.4), (0.8, 0.8, 0.8), material("red", (0.7, 0.1, 0.08), 0.5))
    return camera((0, -2.8, 1.4), (0, 0.8, 0.5), 28), "glass sphere under a small area lamp: caustics"


def glass_outdoors():
    world(sky=(25, 300), strength=0.25)
    plane((0, 0, 0), 30, material("sand", (0.7, 0.6, 0.45), 0.9))
    box((-0.9, 0, 0.6), (1.2, 1.2, 1.2), glass("glass-cube", (0.85, 0.95, 1)), 0.6)
    cylinder((1, 0.5, 0.7), 0.4, 1.4, glass("glass-rough", (1, 0.95, 0.85), 0.15))
    sphere((0.2, 2, 0.4), 0.4, material("blue", (0.1, 0.2, 0.6), 0.4))
    return camera((0, -5, 1.8), (0, 0.5, 0.5), 35), "clear and rough glass in sun and sky"


def metal_spheres():
    world(0.15, (0.6, 0.7, 0.9))
    plane((0, 0, 0), 30, material("checker", (0.45, 0.45, 0.45), 0.7))
    lamp("AREA", (-2, -2, 4), 300, 0.5, rot=(0.5, -0.4, 0))
    for i, (rough, rgb) in enumerate([(0.02, (0.95, 0.93, 0.88)), (0.15, (1, 0.76, 0.33)),
                                     (0.35, (0.95, 0.64, 0.54)), (0.6, (0.56, 0.57, 0.58))]):
        sphere((-2.25 + 1.5 * i, 0.5, 0.6), 0.6, material(f"metal{i}", rgb, rough, 1.0))
    return camera((0, -5.5, 2), (0, 0.5, 0.5), 35), "polished to rough metals reflecting a lamp and sky"


def metal_room():
    world()
    room(6, 6, 3, material("walls", (0.7, 0.7, 0.7), 0.9))
    chrome = material("chrome", (0.9, 0.9, 0.9), 0.05, 1.0)
    box((0, 2.9, 1.5), (4, 0.05, 2.5), chrome)  # a mirror wall
    lamp("POINT", (0.5, -1, 2.6), 80, 0.05, (1, 0.85, 0.7))
    torus((-0.8, 1.2, 0.3), 0.4, 0.15, material("copper", (0.95, 0.64, 0.54), 0.2, 1.0))
    cylinder((0.9, 1.0, 0.6), 0.35, 1.2, material("brushed", (0.8, 0.8, 0.8), 0.35, 1.0))
    return camera((0, -2.8, 1.5), (0, 1.5, 0.8), 26), "a mirror wall and metal objects indoors"


def dark_window():
    world(sky=(30, 90), strength=0.3)
    wall = material("wall", (0.7, 0.68, 0.62), 0.9)
    room(6, 6, 3, wall, skip=("right",))
    # The right wall with one window: four boxes around the opening.
    box((3.05, -2, 1.5), (0.1, 2, 3), wall)
    box((3.05, 2, 1.5), (0.1, 2, 3), wall)
    box((3.05, 0, 0.5), (0.1, 2, 1), wall)
    box((3.05, 0, 2.6), (0.1, 2, 0.8), wall)
    box((0, 1.5, 0.4), (1.5, 0.8, 0.8), material("sofa", (0.3, 0.15, 0.1), 0.8))
    return camera((-2.8, -2.8, 1.6), (1, 1, 1), 22), "a room lit by sun and sky through one window"


def dark_hidden_lamp():
    world()
    room(8, 6, 3, material("wall", (0.65, 0.65, 0.65), 0.9))
    box((1, 0, 1.25), (0.1, 6, 2.5), material("partition", (0.65, 0.65, 0.65), 0.9))
    lamp("POINT", (2.5, 0, 2.0), 150, 0.05, (1, 0.85, 0.7))  # behind the partition
    sphere((-1.5, 0.5, 0.5), 0.5, material("green", (0.2, 0.5, 0.2), 0.5))
    box((-2.5, -1, 0.4), (0.8, 0.8, 0.8), material("blue", (0.2, 0.25, 0.6), 0.6), 0.4)
    return camera((-3.7, -2.7, 1.5), (0.5, 1, 1), 24), "the only lamp hides behind a wall that stops short of the ceiling"


def lamp_box():
    world()
    room(4, 6, 3, material("white", (0.75, 0.75, 0.72), 0.9))
    box((-1.95, 0, 1.5), (0.08, 5.9, 2.9), material("red", (0.65, 0.08, 0.06), 0.9))
    box((1.95, 0, 1.5), (0.08, 5.9, 2.9), material("green", (0.1, 0.5, 0.12), 0.9))
    # A visible ceiling panel, slightly below the ceiling so its edge meets a dark seam.
    plane((0, 0.6, 2.98), 0.8, emissive("panel", (1, 0.92, 0.8), 25), (math.pi, 0, 0))
    box((-0.6, 0.9, 0.6), (0.9, 0.9, 1.2), material("block", (0.7, 0.7, 0.7), 0.8), 0.35)
    sphere((0.7, 0.2, 0.45), 0.45, material("ball", (0.75, 0.75, 0.75), 0.6))
    return camera((0, -2.8, 1.5), (0, 0.6, 1.9), 24), "a box lit by a visible ceiling panel: lamp-beside-ceiling edges"


def lamp_metal_glass_box():
    world()
    room(4, 6, 3, material("white", (0.75, 0.75, 0.72), 0.9))
    plane((0, 0.4, 2.98), 0.6, emissive("panel", (1, 0.95, 0.9), 40), (math.pi, 0, 0))
    sphere((-0.8, 0.6, 0.55), 0.55, material("chrome", (0.92, 0.92, 0.92), 0.03, 1.0))
    sphere((0.8, 0.2, 0.55), 0.55, glass("glass"))
    box((0, 1.5, 0.35), (1.2, 0.6, 0.7), material("gold", (1, 0.76, 0.33), 0.25, 1.0))
    return camera((0, -2.8, 1.5), (0, 0.5, 1.6), 24), "a visible lamp over metal and glass: leaks through reflections and refractions"


SCENES = {f.__name__.replace("_", "-"): f for f in (
    sun_sky_courtyard, sun_sky_low, sun_through_pergola, small_lamps_room, spot_dark_stage,
    emissive_strips, neon_sign, glass_caustic, glass_outdoors, metal_spheres, metal_room,
    dark_window, dark_hidden_lamp, lamp_box, lamp_metal_glass_box)}


# ---- rendering ------------------------------------------------------------------------

def settings(size):
    """Unbiased Cycles: no clamping or glossy blur, fixed samples, no denoiser, so the
    reference converges to the same image the noisy renders estimate."""
    s = bpy.context.scene
    s.render.engine = "CYCLES"
    c = s.cycles
    c.device = "CPU"
    c.use_adaptive_sampling = False
    c.use_denoising = False
    c.sample_clamp_direct = 0.0
    c.sample_clamp_indirect = 0.0
    c.blur_glossy = 0.0
    c.use_animated_seed = False
    c.max_bounces = 12
    c.transparent_max_bounces = 8
    c.transmission_bounces = 12
    s.render.resolution_x = s.render.resolution_y = size
    s.render.resolution_percentage = 100
    s.render.threads_mode = "AUTO"
    s.render.use_compositing = False
    s.render.use_sequencer = False
    s.view_settings.view_transform = "Standard"  # EXR keeps linear scene values anyway
    view = s.view_layers[0]
    view.cycles.denoising_store_passes = True  # Denoising Albedo, Denoising Normal
    view.use_pass_normal = True
    view.use_pass_z = True
    s.render.image_settings.file_format = "OPEN_EXR_MULTILAYER"
    s.render.image_settings.color_depth = "32"
    s.render.image_settings.exr_codec = "ZIP"


def render(path, spp, seed):
    s = bpy.context.scene
    s.cycles.samples = spp
    s.cycles.seed = seed
    s.render.filepath = path
    t0 = time.time()
    bpy.ops.render.render(write_still=True)
    return time.time() - t0


def seed_for(name, tag):
    """A stable seed per scene and render (crc32: the same across runs and machines)."""
    return zlib.crc32(f"{name}/{tag}".encode()) & 0x7FFFFFFF


def main(argv):
    if argv and argv[0] == "--list":
        print("temc-cycles-scenes:", ",".join(SCENES))
        return
    out, name, size, spps, ref_spp = argv[0], argv[1], int(argv[2]), argv[3], int(argv[4])
    bpy.ops.wm.read_factory_settings(use_empty=True)
    cam, about = SCENES[name]()
    settings(size)
    raw = os.path.join(out, "raw")
    os.makedirs(raw, exist_ok=True)
    times = {"noisy": {}, "reference": None}
    for spp in [int(s) for s in spps.split(",")]:
        # Independent seeds per spp (not prefixes of one render, unlike temc-render).
        times["noisy"][spp] = render(os.path.join(raw, f"spp{spp:04d}.exr"), spp, seed_for(name, spp))
    times["reference"] = render(os.path.join(raw, "ref.exr"), ref_spp, seed_for(name, "ref"))
    with open(os.path.join(out, "camera.json"), "w") as f:
        json.dump({**cam, "about": about, "blender": bpy.app.version_string}, f, indent=1)
    with open(os.path.join(out, "timings.json"), "w") as f:
        json.dump(times, f, indent=1)
    print(f"temc-cycles: {name} {size}px noisy {sum(times['noisy'].values()):.1f}s "
          f"reference {ref_spp}spp {times['reference']:.1f}s")


main(sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else [])
