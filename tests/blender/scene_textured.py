"""scene_textured.py -- a room whose floor and walls are image textures.

Run by Blender: blender -b --factory-startup --python scene_textured.py
-- OUTDIR.  Writes OUTDIR/textured.gltf (+ .bin, carpet.png, wood.jpg,
checker.png, oak.png), .points and .json (see blendlib.py).

A 5 x 4 x 3 m room modelled as one box facing in, a designer's way:
textures made in Blender (image pixels: a dark tufted carpet, wood boards
saved as JPEG, a checker of two known greys, a lighter oak for the table)
on Principled BSDF base colours, box-projected UVs in metres.  Every
textured surface holds a whole number of texture repeats, so the mean
reflectance of each textured surface is its texture's mean, which the
script records for the test (per object: 'texture_means').  Light: two
emissive ceiling panels.  Points: the 0.8 m work plane, the floor, the
table top and the walls.
"""
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import blendlib as bl  # noqa: E402

W, D, H = 5.0, 4.0, 3.0
outdir = bl.args()[0]
bl.empty_scene()
rng = np.random.default_rng(7)

carpet, carpet_mean = bl.image(outdir, "carpet", bl.carpet(rng, 256))
wood, wood_mean = bl.image(outdir, "wood", bl.wood(rng, 256), fmt="JPEG")
check, check_mean = bl.image(outdir, "checker", bl.checker(128, 8, 0.9, 0.45))
oak, oak_mean = bl.image(outdir, "oak", bl.wood(rng, 128, level=0.8))

m_carpet = bl.material("carpet", tex=carpet, two_sided=False)
m_wood = bl.material("wood_panels", tex=wood, two_sided=False)
m_check = bl.material("checker", tex=check, two_sided=False)
m_oak = bl.material("oak", tex=oak)
m_ceiling = bl.material("ceiling", (0.8, 0.8, 0.8), two_sided=False)
m_panel = bl.material("panel", (0.3, 0.3, 0.3), emit=1500.0,
                      two_sided=False)
m_grey = bl.material("cabinet", (0.45, 0.45, 0.5))

# The room: floor, ceiling and walls as separate objects facing in.
v = [(x, y, z) for z in (0, H) for y in (0, D) for x in (0, W)]
bl.mesh_object("floor", v, [[0, 1, 3, 2]], m_carpet, uv_tile=1.0)
bl.mesh_object("ceiling", v, [[4, 6, 7, 5]], m_ceiling)
bl.mesh_object("wall_wood", v, [[0, 4, 5, 1]], m_wood, uv_tile=1.0)
bl.mesh_object("walls_checker", v, [[2, 3, 7, 6], [0, 2, 6, 4],
                                    [1, 5, 7, 3]], m_check, uv_tile=0.5)
for i, x in enumerate((1.2, 3.2)):
    bl.plane(f"panel{i}", bl.quad(x, 1.7, H - 0.01, 0.6, 0.6, 0), m_panel,
             flip=True)
# A table (top 1.6 x 0.8 m, 0.04 thick, four legs) and a cabinet.
bl.box("table_top", 1.7, 1.6, 0.72, 3.3, 2.4, 0.76, m_oak, uv_tile=0.8)
for i, (x, y) in enumerate(((1.75, 1.65), (3.2, 1.65), (1.75, 2.3),
                            (3.2, 2.3))):
    bl.box(f"table_leg{i}", x, y, 0, x + 0.05, y + 0.05, 0.72, m_oak,
           uv_tile=0.8)
bl.box("cabinet", 4.5, 0.9, 0, 4.95, 1.7, 1.2, m_grey)

up = (0, 0, 1)
points = []
for x in (0.6, 1.5, 3.5, 4.4):
    for y in (0.6, 2.0, 3.4):
        points.append(((x, y, 0.8), up))
for x, y in ((0.4, 3.6), (2.5, 1.2), (4.0, 3.0)):
    points.append(((x, y, 0.001), up))
points.append(((2.5, 2.0, 0.761), up))  # on the table
for z in (0.5, 1.5):
    points.append(((2.5, 0.001, z), (0, 1, 0)))  # the wood wall
    points.append(((0.001, 2.0, z), (1, 0, 0)))  # a checker wall

means = {"floor": carpet_mean, "wall_wood": wood_mean,
         "walls_checker": check_mean}
bl.export(outdir, "textured", points, {
    "scene": "textured",
    "images": 4,
    "texture_means": {k: list(v) for k, v in means.items()},
    "jpeg_objects": ["wall_wood"]})
