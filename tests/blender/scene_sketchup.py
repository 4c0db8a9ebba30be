"""scene_sketchup.py -- an office modelled the way SketchUp models arrive.

Run by Blender: blender -b --factory-startup --python scene_sketchup.py
-- OUTDIR.  Writes OUTDIR/sketchup.gltf (+ .bin), .points and .json (see
blendlib.py).

What makes it SketchUp-like:
  - the building is modelled in millimetres under an empty scaled by
    0.001, the desk in centimetres under an empty scaled by 0.01, the
    rest in metres (the scene's unit is the metre throughout);
  - faces are n-gons: a wall with a door cut into its outline (a concave
    8-gon), a hexagonal desk top, 16-gon legs, 24-gon round downlights;
    Blender's exporter triangulates them;
  - many small separate objects: 48 books, each an object of its own;
  - components: one chair mesh shared by five linked duplicates (glTF
    mesh instancing), a pendant lamp collection instanced twice;
  - nested transforms with non-uniform scale (a shelf component
    stretched 0.6 x 2.5 x 1, holding boards modelled as unit boxes) and
    mirrors (a chair and a cabinet with a negative scale); the chairs are
    one-sided (backface culling on), so their fronts depend on the
    mirror being handled.
Light: the downlights (emissive), and a punctual point light for the
desk lamp, exported in the exporter's default 'SPEC' lighting mode (see
LAMP_CD below).  Points: the 0.8 m work plane, the floor, the walls.
"""
import math
import os
import sys

import bpy

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import blendlib as bl  # noqa: E402

W, D, H = 8000, 6000, 2700  # the room, millimetres
# Blender 3.4's exporter writes a point light's intensity as
# energy / (4 pi) x 683 in its default 'SPEC' mode (watts as lumens at
# 683 lm/W, over the sphere: candela); so energy = cd x 4 pi / 683.
LAMP_CD = 60.0

outdir = bl.args()[0]
bl.empty_scene()
scn = bpy.context.scene

wall = bl.material("wall", (0.7, 0.68, 0.62), two_sided=False)
floor = bl.material("floor", (0.2, 0.2, 0.22), two_sided=False)
ceiling = bl.material("ceiling", (0.85, 0.85, 0.85), two_sided=False)
downlight = bl.material("downlight", (0.5, 0.5, 0.5), emit=3000.0,
                        two_sided=False)
wood = bl.material("desk", (0.45, 0.3, 0.18))
metal = bl.material("legs", (0.3, 0.3, 0.32))
chair = bl.material("chair", (0.15, 0.25, 0.45), two_sided=False)
shelf = bl.material("shelf", (0.6, 0.6, 0.58))
shade = bl.material("shade", (0.75, 0.75, 0.7))
cabinet = bl.material("cabinet", (0.5, 0.4, 0.35), two_sided=False)
books = [bl.material(f"book{i}", c) for i, c in enumerate(
    ((0.5, 0.1, 0.1), (0.1, 0.3, 0.5), (0.6, 0.55, 0.4), (0.1, 0.1, 0.1)))]


def empty(name, loc=(0, 0, 0), scale=(1, 1, 1), rot=(0, 0, 0), parent=None):
    e = bpy.data.objects.new(name, None)
    scn.collection.objects.link(e)
    e.parent = parent
    e.location, e.scale, e.rotation_euler = loc, scale, rot
    return e


# The building, in millimetres.
mm = empty("building_mm", scale=(0.001, 0.001, 0.001))
v = [(x, y, z) for z in (0, H) for y in (0, D) for x in (0, W)]
bl.mesh_object("floor", v, [[0, 1, 3, 2]], floor, parent=mm)
bl.mesh_object("ceiling", v, [[4, 6, 7, 5]], ceiling, parent=mm)
bl.mesh_object("walls", v, [[2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]],
               wall, parent=mm)
# The y = 0 wall with a door (1000..1900 mm, 2100 high): one 8-gon.
door = [(0, 0, 0), (0, 0, H), (W, 0, H), (W, 0, 0), (1900, 0, 0),
        (1900, 0, 2100), (1000, 0, 2100), (1000, 0, 0)]
bl.mesh_object("door_wall", door, [list(range(8))], wall, parent=mm)
for i, (x, y) in enumerate(((2000, 2000), (6000, 2000), (2000, 4200),
                            (6000, 4200))):
    ring = [(px, py, H - 5) for px, py in bl.ngon(24, 150, x, y)]
    bl.mesh_object(f"downlight{i}", ring, [list(range(24))[::-1]],
                   downlight, parent=mm)

# The desk, in centimetres: a hexagonal top on a 16-gon column.
cm = empty("desk_cm", loc=(2.5, 3.2, 0), scale=(0.01, 0.01, 0.01))
bl.prism("desk_top", bl.ngon(6, 80), 72, 75, wood, parent=cm)
bl.prism("desk_leg", bl.ngon(16, 5), 0, 72, metal, parent=cm)

# Chairs: one mesh, five linked duplicates, one of them mirrored.
seat = [(-0.22, -0.22, 0.42, 0.22, 0.22, 0.46),
        (-0.22, 0.18, 0.46, 0.22, 0.22, 0.9)]
legs = [(x, y, 0, x + 0.03, y + 0.03, 0.42)
        for x in (-0.2, 0.17) for y in (-0.2, 0.17)]
c0 = bl.boxes("chair", seat + legs, chair, loc=(2.5, 2.15, 0),
              rot=(0, 0, math.pi))
for i, (x, y, a, sx) in enumerate(((3.5, 3.2, -math.pi / 2, 1),
                                   (2.5, 4.25, 0, 1),
                                   (1.5, 3.2, math.pi / 2, 1),
                                   (5.0, 1.0, 0.3, -1))):
    c = c0.copy()  # shares c0's mesh: a linked duplicate
    c.name = f"chair{i + 1}"
    scn.collection.objects.link(c)
    c.location, c.rotation_euler, c.scale = (x, y, 0), (0, 0, a), (sx, 1, 1)

# A shelf component stretched non-uniformly; its boards are unit boxes.
sh = empty("shelf", loc=(7.6, 1.5, 0), scale=(0.6, 2.5, 1.0))
bl.boxes("shelf_boards", [(0, 0, z, 1, 1, z + 0.03)
                          for z in (0.1, 0.5, 0.9, 1.3, 1.7)] +
         [(0, 0, 0, 1, 0.02, 1.8), (0, 0.98, 0, 1, 1, 1.8)],
         shelf, parent=sh, loc=(-0.5, 0, 0))
# Books: separate small objects standing on the boards.
for k in range(48):
    board, j = divmod(k, 12)
    y = 1.6 + j * 0.19
    z = 0.13 + board * 0.4
    bl.box(f"book{k}", 7.35, y, z, 7.55, y + 0.04 + 0.01 * (k % 3),
           z + 0.22 + 0.02 * (k % 4), books[k % 4])

# A cabinet against the other wall, mirrored in y.
cab = bl.box("cabinet", 0, 0, 0, 1.2, 0.5, 0.75, cabinet,
             loc=(0.1, 5.9, 0), scale=(1, -1, 1))

# A pendant lamp collection (a 12-gon shade), instanced twice.
lamp = bpy.data.collections.new("pendant")
shade_in = [(x, y, 0.0) for x, y in bl.ngon(12, 0.25)]
shade_out = [(x, y, 0.18) for x, y in bl.ngon(12, 0.12)]
me = bpy.data.meshes.new("pendant_shade")
me.from_pydata(shade_in + shade_out, [],
               [[i, (i + 1) % 12, 12 + (i + 1) % 12, 12 + i]
                for i in range(12)] + [list(range(12, 24))])
me.materials.append(shade)
lamp.objects.link(bpy.data.objects.new("pendant_shade", me))
for i, x in enumerate((4.5, 6.0)):
    e = empty(f"pendant{i}", loc=(x, 3.5, 1.9))
    e.instance_type = "COLLECTION"
    e.instance_collection = lamp

# The desk lamp: a point light, exported as KHR_lights_punctual.
ld = bpy.data.lights.new("desk_lamp", "POINT")
ld.energy = LAMP_CD * 4 * math.pi / 683
ld.shadow_soft_size = 0
lo = bpy.data.objects.new("desk_lamp", ld)
scn.collection.objects.link(lo)
lo.location = (2.2, 3.4, 1.2)

up = (0, 0, 1)
points = []
for x in (0.8, 2.0, 3.3, 4.6, 6.0, 7.0):
    for y in (0.8, 2.6, 4.6):
        points.append(((x, y, 0.8), up))
for x, y in ((1.0, 1.5), (4.0, 5.0), (6.5, 4.0)):
    points.append(((x, y, 0.001), up))
points.append(((2.9, 3.2, 0.751), up))  # on the desk top
for z in (0.6, 1.6):
    points.append(((0.001, 2.5, z), (1, 0, 0)))
    points.append(((4.0, 5.999, z), (0, -1, 0)))
    points.append(((3.0, 0.001, z), (0, 1, 0)))

bl.export(outdir, "sketchup", points, {
    "scene": "sketchup", "lamp_cd": LAMP_CD}, lights=True)
