"""blendlib.py -- what the scene scripts in tests/blender/ share.

Imported by the scripts Blender runs (blender -b --factory-startup
--python SCRIPT -- OUTDIR ...), never by the system Python: it needs bpy.
It builds scenes the way a designer does in Blender's own terms --
meshes and objects, Principled BSDF materials, image textures made in
Blender and saved as PNG or JPEG, emission for the luminaires -- and
exports them with Blender's bundled glTF exporter as .gltf + .bin +
images.

Beside the export each script writes, for the test to read:
  NAME.points  the points to query, 'x y z nx ny nz' in glTF axes (+Y up):
               Blender is +Z up and its exporter maps (x, y, z) to
               (x, z, -y), so points are converted the same way here;
  NAME.json    what the scene should read as: triangle count, the mean
               linear reflectance of each texture, light intensities asked
               for (see meta()).

Units: metres (Blender's default unit scale 1); emission strength is the
luminance luxrad reads (cd/m2: the exporter writes Emission colour x
strength as emissiveFactor, folding a strength above 1 into
KHR_materials_emissive_strength).
"""
import json
import math
import os
import sys

import bmesh
import bpy
import numpy as np


def args():
    """The arguments after '--' on Blender's command line."""
    argv = sys.argv
    return argv[argv.index("--") + 1:] if "--" in argv else []


def empty_scene():
    """A scene with nothing in it, metres."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.context.scene.unit_settings.system = "METRIC"
    bpy.context.scene.unit_settings.scale_length = 1.0


# ------------------------------------------------------------- textures

def srgb_to_linear(v):
    v = np.asarray(v, dtype=float)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def image(outdir, name, rgb, fmt="PNG"):
    """Image NAME from rgb (H x W x 3, sRGB-encoded values in [0, 1], row 0
    at the bottom as Blender stores it), saved as OUTDIR/NAME.png or .jpg.
    Returns (image, mean linear RGB of the 8-bit texels that were saved)."""
    h, w, _ = rgb.shape
    img = bpy.data.images.new(name, w, h, alpha=False)
    px = np.ones((h, w, 4), dtype=np.float32)
    px[:, :, :3] = np.clip(rgb, 0, 1)
    img.pixels.foreach_set(px.ravel())
    ext = "png" if fmt == "PNG" else "jpg"
    img.filepath_raw = os.path.join(outdir, f"{name}.{ext}")
    img.file_format = fmt
    img.save()
    # The mean the file holds: 8-bit sRGB (JPEG's loss aside).
    q = np.round(np.clip(rgb, 0, 1) * 255) / 255
    return img, srgb_to_linear(q).reshape(-1, 3).mean(axis=0)


def noise(rng, h, w, base, amp, blur=0):
    """Grey noise around base (sRGB), smoothed by a box of 2*blur+1."""
    n = rng.random((h, w)) - 0.5
    for _ in range(blur):
        n = (n + np.roll(n, 1, 0) + np.roll(n, -1, 0) +
             np.roll(n, 1, 1) + np.roll(n, -1, 1)) / 5
    return base + amp * n / max(np.abs(n).max(), 1e-9)


def tinted(grey, tint):
    """An H x W grey array tinted by an RGB triple (multiplied)."""
    return grey[:, :, None] * np.asarray(tint)[None, None, :]


def carpet(rng, size, level=0.42):
    """Dark tufted carpet: fine noise around level (sRGB), bluish."""
    return tinted(noise(rng, size, size, level, 0.25, blur=1),
                  (0.85, 0.9, 1.0))


def wood(rng, size, level=0.62, boards=4):
    """Wood boards: grain stripes along x, planks of varying shade."""
    y = np.arange(size)[:, None] / size
    x = np.arange(size)[None, :] / size
    plank = (y * boards).astype(int)
    shade = 1 + 0.15 * (rng.random(boards) - 0.5)
    grain = 0.08 * np.sin(2 * math.pi * (x * 3 + 40 * y +
                                         0.3 * np.sin(6 * math.pi * x)))
    g = level * shade[plank] + grain + noise(rng, size, size, 0, 0.05)
    return tinted(g, (1.0, 0.78, 0.55))


def checker(size, squares, a, b):
    """A checker of squares x squares cells, sRGB values a and b."""
    i = (np.arange(size) * squares // size)
    cell = (i[:, None] + i[None, :]) % 2
    g = np.where(cell == 0, a, b).astype(float)
    return np.repeat(g[:, :, None], 3, axis=2)


# ------------------------------------------------------------- materials

def material(name, color=(0.8, 0.8, 0.8), tex=None, emit=0.0,
             emit_color=(1, 1, 1), two_sided=True):
    """A Principled BSDF material: base colour (linear RGB) or an image
    texture, emission strength emit (cd/m2 to luxrad), Blender's backface
    culling off (the default: the exporter writes doubleSided) unless
    two_sided is False."""
    m = bpy.data.materials.new(name)
    m.use_nodes = True
    nt = m.node_tree
    bsdf = nt.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*color, 1)
    bsdf.inputs["Metallic"].default_value = 0
    bsdf.inputs["Roughness"].default_value = 1
    if tex is not None:
        node = nt.nodes.new("ShaderNodeTexImage")
        node.image = tex
        nt.links.new(node.outputs["Color"], bsdf.inputs["Base Color"])
    if emit > 0:
        bsdf.inputs["Emission"].default_value = (*emit_color, 1)
        bsdf.inputs["Emission Strength"].default_value = emit
    m.use_backface_culling = not two_sided
    return m


# ------------------------------------------------------------- meshes

def mesh_object(name, verts, faces, mat=None, uv_tile=None, parent=None,
                loc=(0, 0, 0), scale=(1, 1, 1), rot=(0, 0, 0)):
    """An object from vertices and faces (any number of corners: n-gons
    are kept, the exporter triangulates them).  uv_tile: box-projected
    UVs, one texture repeat per uv_tile metres of the mesh's own
    coordinates."""
    me = bpy.data.meshes.new(name)
    me.from_pydata(verts, [], faces)
    me.update()
    if mat is not None:
        me.materials.append(mat)
    if uv_tile is not None:
        box_uv(me, uv_tile)
    ob = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(ob)
    ob.parent = parent
    ob.location = loc
    ob.scale = scale
    ob.rotation_euler = rot
    return ob


def box_uv(me, tile):
    """UVs projected along each face's dominant normal axis."""
    uv = me.uv_layers.new(name="UVMap")
    for poly in me.polygons:
        ax = int(np.argmax(np.abs(poly.normal)))
        u, v = [a for a in range(3) if a != ax]
        for li in poly.loop_indices:
            co = me.vertices[me.loops[li].vertex_index].co
            uv.data[li].uv = (co[u] / tile, co[v] / tile)


def quad(x0, y0, z0, dx, dy, dz):
    """Four corners of an axis-aligned rectangle: the two non-zero of
    (dx, dy, dz) span it from (x0, y0, z0)."""
    p = (x0, y0, z0)
    d = [(dx, 0, 0), (0, dy, 0), (0, 0, dz)]
    span = [e for e in d if any(e)]
    a, b = span
    return [p, tuple(p[i] + a[i] for i in range(3)),
            tuple(p[i] + a[i] + b[i] for i in range(3)),
            tuple(p[i] + b[i] for i in range(3))]


def plane(name, corners, mat, flip=False, uv_tile=None, **kw):
    """One single-polygon plane; flip reverses its winding (its front)."""
    face = [0, 1, 2, 3][::-1] if flip else [0, 1, 2, 3]
    return mesh_object(name, corners, [face], mat, uv_tile=uv_tile, **kw)


def box_geom(x0, y0, z0, x1, y1, z1, inward=False, base=0):
    """Vertices and faces of an axis-aligned box, six quads facing out (or
    in: a room); face indices start at base."""
    v = [(x, y, z) for z in (z0, z1) for y in (y0, y1) for x in (x0, x1)]
    faces = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3],
             [0, 4, 6, 2], [1, 3, 7, 5]]
    if inward:
        faces = [f[::-1] for f in faces]
    return v, [[base + i for i in f] for f in faces]


def boxes(name, extents, mat, inward=False, **kw):
    """One object of several boxes, each (x0, y0, z0, x1, y1, z1)."""
    verts, faces = [], []
    for e in extents:
        v, f = box_geom(*e, inward=inward, base=len(verts))
        verts += v
        faces += f
    return mesh_object(name, verts, faces, mat, **kw)


def box(name, x0, y0, z0, x1, y1, z1, mat, inward=False, **kw):
    """An axis-aligned box as one object."""
    return boxes(name, [(x0, y0, z0, x1, y1, z1)], mat, inward, **kw)


def prism(name, outline, z0, z1, mat, **kw):
    """A vertical prism: an n-gon outline (counter-clockwise from above)
    for its top and bottom, one quad per side."""
    n = len(outline)
    v = [(x, y, z0) for x, y in outline] + [(x, y, z1) for x, y in outline]
    faces = [list(range(n))[::-1], list(range(n, 2 * n))]
    faces += [[i, (i + 1) % n, n + (i + 1) % n, n + i] for i in range(n)]
    return mesh_object(name, v, faces, mat, **kw)


def ngon(n, r, cx=0.0, cy=0.0, phase=0.0):
    """A regular n-gon's corners, counter-clockwise."""
    return [(cx + r * math.cos(phase + 2 * math.pi * i / n),
             cy + r * math.sin(phase + 2 * math.pi * i / n))
            for i in range(n)]


# ------------------------------------------------------------- output

def to_gltf(p):
    """Blender +Z up to glTF +Y up, as the exporter converts."""
    x, y, z = p
    return (x, z, -y)


def triangles():
    """Triangles the export holds: every mesh instance of the evaluated
    scene (modifiers applied, collection instances expanded), each n-gon
    as n - 2 triangles."""
    dg = bpy.context.evaluated_depsgraph_get()
    n = 0
    for inst in dg.object_instances:
        if inst.object.type == "MESH":
            n += sum(len(p.vertices) - 2 for p in inst.object.data.polygons)
    return n


def export(outdir, name, points, meta, lights=False):
    """Export the scene as OUTDIR/NAME.gltf + .bin + images and write
    NAME.points (points: (position, normal) in Blender axes, with an
    optional label) and NAME.json (meta, plus the triangle count)."""
    path = os.path.join(outdir, name + ".gltf")
    bpy.ops.export_scene.gltf(
        filepath=path, export_format="GLTF_SEPARATE",
        export_image_format="AUTO", export_apply=True,
        export_lights=lights, export_cameras=False, export_yup=True,
        export_normals=False, export_texcoords=True)
    with open(os.path.join(outdir, name + ".points"), "w") as f:
        f.write(f"# {name}.gltf: points made by its Blender script\n"
                "# x y z nx ny nz (metres, glTF axes)\n")
        for pt in points:
            pos, nrm = pt[0], pt[1]
            f.write(" ".join(f"{c:.4f}" for c in
                             to_gltf(pos) + to_gltf(nrm)) + "\n")
    meta = dict(meta, triangles=triangles(), points=len(points))
    with open(os.path.join(outdir, name + ".json"), "w") as f:
        json.dump(meta, f, indent=1, default=float)
    print(f"blendlib: wrote {path}")
