"""scene_interior.py -- a large textured open-plan office floor.

Run by Blender: blender -b --factory-startup --python scene_interior.py
-- OUTDIR [COLUMNS ROWS].  Writes OUTDIR/interior.gltf (+ .bin, five
textures of 1024 and 2048 px), .points and .json (see blendlib.py).
tests/bench/textured_interior.sh uses it for load time and memory.

A 32 x 22 x 3 m floor with COLUMNS x ROWS workstations (default 10 x 14,
about 234,000 triangles), made as a designer makes one: a desk and a
chair modelled once, given detail by modifiers (bevelled desk edges, a
subdivision-surface chair) and repeated by two array modifiers; the
exporter applies them.  Textures made in Blender: a carpet (2048 px PNG),
wall fabric (2048 px JPEG), ceiling tiles (1024 px PNG), desk wood
(1024 px JPEG, also used, tinted, by the cabinets: one image, two
materials) and chair fabric (1024 px PNG).  Light: a grid of emissive
ceiling panels.  Points: a grid on the 0.8 m work plane.
"""
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import blendlib as bl  # noqa: E402

W, D, H = 32.0, 22.0, 3.0
argv = bl.args()
outdir = argv[0]
cols, rows = (int(argv[1]), int(argv[2])) if len(argv) > 2 else (10, 14)
bl.empty_scene()
rng = np.random.default_rng(11)

carpet, _ = bl.image(outdir, "carpet", bl.carpet(rng, 2048))
fabric, _ = bl.image(outdir, "wall_fabric",
                     bl.tinted(bl.noise(rng, 2048, 2048, 0.75, 0.1, blur=2),
                               (1.0, 0.97, 0.9)), fmt="JPEG")
tiles = bl.checker(1024, 2, 0.92, 0.88)
tiles[::256, :, :] = 0.5  # the grid between tiles
tiles[:, ::256, :] = 0.5
ceil, _ = bl.image(outdir, "ceiling_tiles", tiles)
wood, _ = bl.image(outdir, "desk_wood", bl.wood(rng, 1024), fmt="JPEG")
seat, _ = bl.image(outdir, "chair_fabric",
                   bl.tinted(bl.noise(rng, 1024, 1024, 0.35, 0.2),
                             (0.3, 0.45, 0.8)))

m_floor = bl.material("carpet", tex=carpet, two_sided=False)
m_wall = bl.material("wall_fabric", tex=fabric, two_sided=False)
m_ceil = bl.material("ceiling_tiles", tex=ceil, two_sided=False)
m_desk = bl.material("desk", tex=wood)
m_cab = bl.material("cabinet", (0.7, 0.7, 0.75), tex=wood)
m_chair = bl.material("chair", tex=seat)
m_metal = bl.material("metal", (0.35, 0.35, 0.38))
m_panel = bl.material("panel", (0.3, 0.3, 0.3), emit=1800.0,
                      two_sided=False)

# The room, facing in.
v = [(x, y, z) for z in (0, H) for y in (0, D) for x in (0, W)]
bl.mesh_object("floor", v, [[0, 1, 3, 2]], m_floor, uv_tile=2.0)
bl.mesh_object("ceiling", v, [[4, 6, 7, 5]], m_ceil, uv_tile=1.2)
bl.mesh_object("walls", v, [[0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4],
                            [1, 5, 7, 3]], m_wall, uv_tile=1.5)
# Ceiling panels, 1.2 x 0.6 m, every 3 x 2.5 m.
for i, x in enumerate(np.arange(1.9, W - 1, 3.0)):
    for j, y in enumerate(np.arange(1.6, D - 1, 2.5)):
        bl.plane(f"panel{i}_{j}", bl.quad(x, y, H - 0.01, 1.2, 0.6, 0),
                 m_panel, flip=True)

# One workstation at (2, 2), arrayed COLUMNS x ROWS every 2.8 x 1.45 m.
X0, Y0, DX, DY = 2.0, 2.0, 2.8, 1.45


def arrayed(ob, bevel=0, subsurf=0):
    if bevel:
        m = ob.modifiers.new("bevel", "BEVEL")
        m.width, m.segments = 0.008, bevel
    if subsurf:
        m = ob.modifiers.new("subsurf", "SUBSURF")
        m.levels = m.render_levels = subsurf
    for axis, count, step in ((0, cols, DX), (1, rows, DY)):
        m = ob.modifiers.new(f"array{axis}", "ARRAY")
        m.count = count
        m.use_relative_offset = False
        m.use_constant_offset = True
        off = [0, 0, 0]
        off[axis] = step
        m.constant_offset_displace = off
    return ob


arrayed(bl.boxes("desk", [(X0, Y0, 0.72, X0 + 1.6, Y0 + 0.8, 0.75),
                          (X0 + 1.7, Y0 + 0.05, 0, X0 + 2.2, Y0 + 0.65,
                           0.65)], m_desk, uv_tile=0.8), bevel=3)
arrayed(bl.boxes("desk_frame", [(X0 + x, Y0 + 0.05, 0, X0 + x + 0.05,
                                 Y0 + 0.75, 0.72) for x in (0.05, 1.5)] +
                 [(X0 + 0.3, Y0 + 0.55, 0.75, X0 + 0.9, Y0 + 0.58, 1.1)],
                 m_metal), bevel=2)
arrayed(bl.boxes("cabinet", [(X0 + 1.72, Y0 + 0.07, 0.65, X0 + 2.18,
                              Y0 + 0.63, 0.67)], m_cab, uv_tile=0.8))
arrayed(bl.boxes("chair", [(X0 + 0.55, Y0 - 0.45, 0.42, X0 + 1.05,
                            Y0 + 0.05, 0.5),
                           (X0 + 0.55, Y0 - 0.5, 0.5, X0 + 1.05,
                            Y0 - 0.42, 1.0),
                           (X0 + 0.77, Y0 - 0.23, 0.05, X0 + 0.83,
                            Y0 - 0.17, 0.42)] +
        [(X0 + x, Y0 - 0.4, 0.62, X0 + x + 0.05, Y0, 0.67)
         for x in (0.5, 1.05)], m_chair, uv_tile=0.5),
        subsurf=2)

up = (0, 0, 1)
points = [((x, y, 0.8), up) for x in (1.0, 8.3, 15.3, 22.3, 30.5)
          for y in (1.2, 8.0, 15.2, 21.0)]
bl.export(outdir, "interior", points, {"scene": "interior", "images": 5,
                                       "materials_textured": 6})
