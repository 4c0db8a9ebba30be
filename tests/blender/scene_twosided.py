"""scene_twosided.py -- a room whose partition and ceiling are single planes.

Run by Blender: blender -b --factory-startup --python scene_twosided.py
-- OUTDIR.  Writes OUTDIR/twosided.gltf (+ .bin), .points and .json (see
blendlib.py).

The room (6 x 4 x 3 m) is a box modelled with its faces turned inward and
backface culling on: its floor and walls are one-sided.  What a designer
draws as single planes, with Blender's default of backface culling off
(so the exporter writes doubleSided), are:
  - the ceiling, one plane;
  - a partition at x = 3 m, 2.6 m high, leaving a 1 m passage, lit from
    both sides: a ceiling panel over each half, of different luminance;
  - a suspended luminous sheet in the left half that emits both down and
    up onto the ceiling (a two-sided emitter).
Points: the 0.8 m work plane in both halves, both faces of the partition,
and the ceiling seen from below (lit mostly by the sheet's upper face).
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import blendlib as bl  # noqa: E402

W, D, H = 6.0, 4.0, 3.0
outdir = bl.args()[0]
bl.empty_scene()

walls = bl.material("walls", (0.6, 0.6, 0.6), two_sided=False)
floor = bl.material("floor", (0.25, 0.22, 0.2), two_sided=False)
plaster = bl.material("plaster", (0.8, 0.8, 0.8))
partition = bl.material("partition", (0.5, 0.55, 0.6))
sheet = bl.material("sheet", (0.3, 0.3, 0.3), emit=400.0)
panel_l = bl.material("panel_left", (0.2, 0.2, 0.2), emit=250.0,
                      two_sided=False)
panel_r = bl.material("panel_right", (0.2, 0.2, 0.2), emit=900.0,
                      two_sided=False)

# Floor and walls: the room box facing in (its top is the ceiling plane's).
v = [(x, y, z) for z in (0, H) for y in (0, D) for x in (0, W)]
bl.mesh_object("floor", v, [[0, 1, 3, 2]], floor)
bl.mesh_object("walls", v, [[0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4],
                            [1, 5, 7, 3]], walls)
# The ceiling, drawn facing up as a single plane would be by default.
bl.plane("ceiling", bl.quad(0, 0, H, W, D, 0), plaster)
# Partition: one plane in x = 3 from y = 0 to 3, 2.6 m high.
bl.plane("partition", bl.quad(3, 0, 0, 0, 3.0, 2.6), partition)
# Luminaires: panels just under the ceiling facing down, the sheet
# hanging 0.7 m below it.
bl.plane("panel_left", bl.quad(1.0, 1.5, H - 0.01, 1.0, 1.0, 0), panel_l,
         flip=True)
bl.plane("panel_right", bl.quad(4.0, 1.5, H - 0.01, 1.0, 1.0, 0), panel_r,
         flip=True)
bl.plane("sheet", bl.quad(0.9, 0.8, H - 0.7, 1.2, 0.6, 0), sheet)

up, down = (0, 0, 1), (0, 0, -1)
points = []
for x in (0.8, 1.5, 2.4, 3.6, 4.5, 5.3):
    for y in (0.7, 2.0, 3.3):
        points.append(((x, y, 0.8), up))
for y in (0.8, 2.2):
    for z in (0.9, 1.8):
        points.append(((2.999, y, z), (-1, 0, 0)))  # left face
        points.append(((3.001, y, z), (1, 0, 0)))  # right face
for x, y in ((1.5, 1.1), (1.5, 3.0), (4.5, 0.8)):
    points.append(((x, y, H - 0.001), down))

bl.export(outdir, "twosided", points, {"scene": "twosided"})
