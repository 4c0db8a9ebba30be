#!/usr/bin/python3
"""make_corpus.py -- write the fuzz harnesses' seed corpus.

Usage: make_corpus.py [OUT_DIR]     (default: corpus/ beside this file)

Writes OUT_DIR/frame/ (connection byte streams: requests and replies as
luxrad's wire protocol frames them), OUT_DIR/args/ (request headers as
JSON objects) and OUT_DIR/gltf/ (small glTF and GLB scenes: a box, strips
and fans, textures in PNG and JPEG, KHR_texture_transform, emissive
strength, KHR_lights_punctual lights, luminaires with a packed IES or
EULUMDAT file, sensor nodes).  Standard library only; the PNG and JPEG
images are written here (the JPEGs are baseline, one DC value per 8 x 8
block).  The output is the same on every run, so the files in the tree
can be regenerated and compared.  Existing files of the same names are
overwritten; others are left alone.
"""
import base64
import json
import os
import struct
import sys
import zlib

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.normpath(os.path.join(HERE, "..", ".."))


def dumps(obj):
    return json.dumps(obj, separators=(",", ":"), ensure_ascii=False)


def write(path, data):
    if isinstance(data, str):
        data = data.encode()
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "wb") as f:
        f.write(data)


# ------------------------------------------------------------------ images

def png(width, height, color_type, depth, rows, extra=b"", filt=0):
    """A PNG of the given raw rows (bytes each, without filter byte)."""
    raw = b""
    for r in rows:
        if filt == 1:  # Sub: each byte less the one a pixel before
            bpp = max(1, {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}[color_type] *
                      depth // 8)
            r = bytes((r[i] - (r[i - bpp] if i >= bpp else 0)) & 0xFF
                      for i in range(len(r)))
        raw += bytes([filt]) + r
    ihdr = struct.pack(">IIBBBBB", width, height, depth, color_type, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + png_chunk(b"IHDR", ihdr) + extra +
            png_chunk(b"IDAT", zlib.compress(raw, 9)) +
            png_chunk(b"IEND", b""))


def png_chunk(kind, body):
    return (struct.pack(">I", len(body)) + kind + body +
            struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF))


def checker_rgb(w, h, a, b):
    return [bytes(sum(((a if (x // 2 + y // 2) % 2 == 0 else b)
                       for x in range(w)), ())) for y in range(h)]


class BitWriter:
    def __init__(self):
        self.out = bytearray()
        self.acc = 0
        self.n = 0

    def put(self, value, nbits):
        for i in range(nbits - 1, -1, -1):
            self.acc = (self.acc << 1) | ((value >> i) & 1)
            self.n += 1
            if self.n == 8:
                self.out.append(self.acc)
                if self.acc == 0xFF:
                    self.out.append(0)  # byte stuffing
                self.acc = 0
                self.n = 0

    def flush(self):
        while self.n:
            self.put(1, 1)  # pad with ones
        return bytes(self.out)


def jpeg(width, height, pixel, gray=False):
    """A baseline JPEG, one DC value a block and no AC energy: pixel(x, y)
    gives (r, g, b) in 0..255; each 8 x 8 block is its mean colour."""
    def seg(marker, body):
        return struct.pack(">BBH", 0xFF, marker, len(body) + 2) + body

    ncomp = 1 if gray else 3
    # All quantisers 8: a flat block of level p has DC 8 (p - 128).
    dqt = seg(0xDB, b"\x00" + bytes([8] * 64))
    comps = b"".join(bytes([c + 1, 0x11, 0]) for c in range(ncomp))
    sof = seg(0xC0, struct.pack(">BHHB", 8, height, width, ncomp) + comps)
    # DC: categories 0..11, each a 4-bit code equal to it.  AC: only
    # end-of-block, the 1-bit code 0.
    dht = seg(0xC4, b"\x00" + bytes([0, 0, 0, 12] + [0] * 12) +
              bytes(range(12)) + b"\x10" + bytes([1] + [0] * 15) + b"\x00")
    sos = seg(0xDA, bytes([ncomp]) +
              b"".join(bytes([c + 1, 0]) for c in range(ncomp)) +
              b"\x00\x3f\x00")
    app0 = seg(0xE0, b"JFIF\x00\x01\x01\x00\x00\x01\x00\x01\x00\x00")

    bw = BitWriter()
    pred = [0] * ncomp
    for by in range(0, height, 8):
        for bx in range(0, width, 8):
            px = [pixel(x, y) for y in range(by, min(by + 8, height))
                  for x in range(bx, min(bx + 8, width))]
            r, g, b = (sum(p[i] for p in px) / len(px) for i in range(3))
            ycc = [0.299 * r + 0.587 * g + 0.114 * b,
                   128 - 0.168736 * r - 0.331264 * g + 0.5 * b,
                   128 + 0.5 * r - 0.418688 * g - 0.081312 * b]
            for c in range(ncomp):
                dc = int(round(ycc[c])) - 128
                diff = dc - pred[c]
                pred[c] = dc
                cat = abs(diff).bit_length()
                bw.put(cat, 4)
                if cat:
                    bw.put(diff if diff >= 0 else diff + (1 << cat) - 1,
                           cat)
                bw.put(0, 1)  # end of block
    return (b"\xff\xd8" + app0 + dqt + sof + dht + sos + bw.flush() +
            b"\xff\xd9")


# ------------------------------------------------------------------- glTF

FLOAT, UBYTE, USHORT, UINT = 5126, 5121, 5123, 5125


class Doc:
    """A glTF document under construction, with one binary buffer."""

    def __init__(self):
        self.blob = bytearray()
        self.j = {"asset": {"version": "2.0", "generator": "make_corpus"}}

    def add(self, key, item):
        self.j.setdefault(key, []).append(item)
        return len(self.j[key]) - 1

    def view(self, data, stride=None):
        while len(self.blob) % 4:
            self.blob.append(0)
        v = {"buffer": 0, "byteOffset": len(self.blob),
             "byteLength": len(data)}
        if stride:
            v["byteStride"] = stride
        self.blob += data
        return self.add("bufferViews", v)

    def accessor(self, fmt, values, ctype, kind, minmax=False, **extra):
        data = b"".join(struct.pack("<" + fmt, *v) if isinstance(v, tuple)
                        else struct.pack("<" + fmt, v) for v in values)
        a = {"bufferView": self.view(data), "componentType": ctype,
             "count": len(values), "type": kind}
        if minmax:
            a["min"] = [min(v[i] for v in values) for i in range(3)]
            a["max"] = [max(v[i] for v in values) for i in range(3)]
        a.update(extra)
        return self.add("accessors", a)

    def positions(self, pts):
        return self.accessor("3f", pts, FLOAT, "VEC3", minmax=True)

    def indices(self, idx, ctype=UINT):
        fmt = {UBYTE: "B", USHORT: "H", UINT: "I"}[ctype]
        return self.accessor(fmt, idx, ctype, "SCALAR")

    def mesh(self, prims, name=None):
        m = {"primitives": prims}
        if name:
            m["name"] = name
        return self.add("meshes", m)

    def node(self, **n):
        return self.add("nodes", n)

    def image(self, data, mime):
        return self.add("images", {"bufferView": self.view(data),
                                   "mimeType": mime})

    def use(self, ext, required=False):
        for key in ["extensionsUsed"] + (["extensionsRequired"]
                                         if required else []):
            lst = self.j.setdefault(key, [])
            if ext not in lst:
                lst.append(ext)

    def gltf(self):
        j = dict(self.j)
        if self.blob:
            j["buffers"] = [{
                "byteLength": len(self.blob),
                "uri": "data:application/octet-stream;base64," +
                       base64.b64encode(bytes(self.blob)).decode()}]
        return dumps(j).encode()

    def glb(self):
        j = dict(self.j)
        blob = bytes(self.blob)
        while len(blob) % 4:
            blob += b"\0"
        if blob:
            j["buffers"] = [{"byteLength": len(blob)}]
        text = dumps(j).encode()
        while len(text) % 4:
            text += b" "
        body = struct.pack("<I4s", len(text), b"JSON") + text
        if blob:
            body += struct.pack("<I4s", len(blob), b"BIN\0") + blob
        return struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body


def quad(x0, y0, z0, du, dv):
    """Four corners p, p + du, p + du + dv, p + dv."""
    p = (x0, y0, z0)
    return [p, tuple(p[i] + du[i] for i in range(3)),
            tuple(p[i] + du[i] + dv[i] for i in range(3)),
            tuple(p[i] + dv[i] for i in range(3))]


def box_doc():
    """A closed 2 m box seen from inside, a lamp panel under its top."""
    d = Doc()
    s = 2.0
    faces = [  # counter-clockwise seen from inside
        quad(0, 0, 0, (0, 0, s), (s, 0, 0)),      # floor, facing +y
        quad(0, s, 0, (s, 0, 0), (0, 0, s)),      # ceiling, facing -y
        quad(0, 0, 0, (s, 0, 0), (0, s, 0)),      # z = 0 wall
        quad(0, 0, s, (0, s, 0), (s, 0, 0)),      # z = s wall
        quad(0, 0, 0, (0, s, 0), (0, 0, s)),      # x = 0 wall
        quad(s, 0, 0, (0, 0, s), (0, s, 0)),      # x = s wall
    ]
    pts = [p for f in faces for p in f]
    idx = []
    for k in range(len(faces)):
        a = 4 * k
        idx += [a, a + 1, a + 2, a, a + 2, a + 3]
    wall = d.add("materials", {"name": "wall", "pbrMetallicRoughness": {
        "baseColorFactor": [0.7, 0.6, 0.5, 1], "metallicFactor": 0}})
    lamp = d.add("materials", {"name": "lamp", "emissiveFactor": [1, 1, 1],
                               "pbrMetallicRoughness": {
                                   "baseColorFactor": [0, 0, 0, 1]}})
    room = d.mesh([{"attributes": {"POSITION": d.positions(pts)},
                    "indices": d.indices(idx, USHORT), "material": wall}],
                  "room")
    lp = quad(0.7, 1.95, 0.7, (0.6, 0, 0), (0, 0, 0.6))
    panel = d.mesh([{"attributes": {"POSITION": d.positions(lp)},
                     "indices": d.indices([0, 1, 2, 0, 2, 3], UBYTE),
                     "material": lamp}], "panel")
    d.j["scenes"] = [{"nodes": [d.node(name="room", mesh=room),
                                d.node(name="panel", mesh=panel)]}]
    d.j["scene"] = 0
    return d


def floor(d, material, uv=None, uv_type=FLOAT, texcoord=0, n=3, size=2.0):
    """An n x n grid of quads on y = 0, facing +y, with UVs; a mesh."""
    pts, uvs, idx = [], [], []
    for j in range(n + 1):
        for i in range(n + 1):
            pts.append((i * size / n, 0.0, j * size / n))
            uvs.append((i * 1.5 / n - 0.25, j * 1.2 / n + 0.1))
    for j in range(n):
        for i in range(n):
            a = j * (n + 1) + i
            idx += [a, a + n + 1, a + 1, a + 1, a + n + 1, a + n + 2]
    attrs = {"POSITION": d.positions(pts)}
    if uv_type == FLOAT:
        attrs["TEXCOORD_%d" % texcoord] = d.accessor("2f", uvs, FLOAT, "VEC2")
    else:
        top = 255 if uv_type == UBYTE else 65535
        fmt = "2B" if uv_type == UBYTE else "2H"
        q = [tuple(int(min(max(c, 0), 1) * top) for c in t) for t in uvs]
        attrs["TEXCOORD_%d" % texcoord] = d.accessor(
            fmt, q, uv_type, "VEC2", normalized=True)
    return d.mesh([{"attributes": attrs, "indices": d.indices(idx),
                    "material": material}], "floor")


def lamp_over(d, y=1.5, strength=None):
    """An emitting 0.5 m panel at height y facing down; its node."""
    mat = {"name": "lamp", "emissiveFactor": [1, 0.9, 0.8],
           "pbrMetallicRoughness": {"baseColorFactor": [0.1, 0.1, 0.1, 1]}}
    if strength is not None:
        mat["extensions"] = {"KHR_materials_emissive_strength": {
            "emissiveStrength": strength}}
        d.use("KHR_materials_emissive_strength")
    m = d.add("materials", mat)
    lp = quad(0.75, y, 0.75, (0.5, 0, 0), (0, 0, 0.5))
    mesh = d.mesh([{"attributes": {"POSITION": d.positions(lp)},
                    "indices": d.indices([0, 1, 2, 0, 2, 3], UBYTE),
                    "material": m}], "lamp")
    return d.node(name="lamp", mesh=mesh)


def textured(img, mime, sampler=None, transform=None, uv_type=FLOAT,
             texcoord=0, factor=(1, 1, 1, 1)):
    d = Doc()
    ti = {"index": 0}
    if texcoord:
        ti["texCoord"] = texcoord
    if transform is not None:
        ti["extensions"] = {"KHR_texture_transform": transform}
        d.use("KHR_texture_transform", required=True)
    tex = {"source": d.image(img, mime)}
    if sampler is not None:
        d.add("samplers", sampler)
        tex["sampler"] = 0
    d.add("textures", tex)
    m = d.add("materials", {"name": "textured", "pbrMetallicRoughness": {
        "baseColorTexture": ti, "baseColorFactor": list(factor),
        "metallicFactor": 0}})
    fl = floor(d, m, uv_type=uv_type,
               texcoord=transform.get("texCoord", texcoord)
               if transform else texcoord)
    d.j["scenes"] = [{"nodes": [d.node(name="floor", mesh=fl), lamp_over(d)]}]
    d.j["scene"] = 0
    return d


def gltf_seeds():
    out = {}
    out["box.gltf"] = box_doc().gltf()
    out["box.glb"] = box_doc().glb()

    # Strips, fans, every index type, no indices, a skipped POINTS.
    d = Doc()
    pts = [(0, 0, 0), (0, 0, 1), (1, 0, 0), (1, 0, 1), (2, 0, 0), (2, 0, 1)]
    pa = d.positions(pts)
    fan = d.positions([(0, 1, 0), (1, 1, 0), (1, 1, 1), (0, 1, 1),
                       (-1, 1, 0.5)])
    m = d.add("materials", {"doubleSided": True, "pbrMetallicRoughness": {
        "baseColorFactor": [0.5, 0.5, 0.5, 1], "metallicFactor": 1}})
    glow = d.add("materials", {"emissiveFactor": [0.5, 0.5, 0.5]})
    mesh = d.mesh([
        {"attributes": {"POSITION": pa}, "mode": 5, "material": m},
        {"attributes": {"POSITION": pa}, "mode": 5,
         "indices": d.indices([0, 1, 2, 3, 4, 5], USHORT)},
        {"attributes": {"POSITION": fan}, "mode": 6,
         "indices": d.indices([0, 1, 2, 3, 4], UBYTE), "material": glow},
        {"attributes": {"POSITION": pa}, "mode": 4,
         "indices": d.indices([0, 2, 1, 2, 3, 1], UINT)},
        {"attributes": {"POSITION": pa}, "mode": 0},
        {"attributes": {"POSITION": pa}, "mode": 1}], "shapes")
    d.j["nodes"] = [{"name": "shapes", "mesh": mesh,
                     "translation": [0, 0.5, 0], "scale": [1, -1, 1]},
                    {"name": "lamp", "mesh": mesh, "matrix":
                     [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 3, 0, 1]}]
    out["strips_fans.gltf"] = d.gltf()  # no "scenes": every root node

    # Textures: PNG in every colour type, JPEG in colour and grey.
    rgb = png(4, 4, 2, 8, checker_rgb(4, 4, (200, 40, 40), (40, 40, 200)))
    out["tex_png.glb"] = textured(rgb, "image/png", sampler={
        "wrapS": 33648, "wrapT": 33071, "magFilter": 9728}).glb()
    grey = png(3, 5, 0, 8, [bytes([y * 50, 255 - y * 50, 128])
                            for y in range(5)],
               extra=png_chunk(b"gAMA", struct.pack(">I", 100000)), filt=1)
    out["tex_png_grey_gamma.gltf"] = textured(
        grey, "image/png", sampler={"wrapS": 10497, "wrapT": 33648}).gltf()
    pal = png(4, 2, 3, 8, [bytes([0, 1, 2, 1]), bytes([2, 2, 0, 1])],
              extra=png_chunk(b"PLTE", bytes([255, 0, 0, 0, 255, 0,
                                              0, 0, 255])) +
              png_chunk(b"tRNS", bytes([128])))
    out["tex_png_palette.glb"] = textured(pal, "image/png").glb()
    rgba16 = png(2, 2, 6, 16, [struct.pack(">8H", 65535, 0, 0, 65535,
                                           0, 65535, 0, 32768),
                               struct.pack(">8H", 0, 0, 65535, 0,
                                           30000, 30000, 30000, 65535)],
                 extra=png_chunk(b"sRGB", b"\x00"))
    out["tex_png_rgba16.gltf"] = textured(
        rgba16, "image/png", uv_type=USHORT).gltf()
    ga = png(2, 2, 4, 8, [bytes([10, 255, 240, 0]), bytes([90, 128, 30, 9])])
    out["tex_png_grey_alpha.glb"] = textured(
        ga, "image/png", uv_type=UBYTE, factor=(0.5, 0.9, 0.9, 1)).glb()

    def colours(x, y):
        return ((x * 30) % 256, (y * 40) % 256, ((x + y) * 20) % 256)
    jp = jpeg(16, 8, colours)
    out["tex_jpeg_transform.gltf"] = textured(
        jp, "image/jpeg", transform={"offset": [0.25, -0.5],
                                     "rotation": 0.3, "scale": [2, 0.5],
                                     "texCoord": 1},
        sampler={"wrapS": 33648, "wrapT": 10497}).gltf()
    jg = jpeg(9, 9, lambda x, y: (x * 28, x * 28, x * 28), gray=True)
    out["tex_jpeg_grey.glb"] = textured(jg, "image/jpeg").glb()

    # Emissive strength, two-sided, a note for an extension not read.
    d = Doc()
    m = d.add("materials", {"doubleSided": True, "pbrMetallicRoughness": {
        "baseColorFactor": [0.8, 0.8, 0.8, 1]}})
    fl = floor(d, m, n=2)
    d.use("KHR_materials_transmission")
    d.j["scenes"] = [{"nodes": [d.node(name="floor", mesh=fl),
                                lamp_over(d, strength=40.0)]}]
    out["emissive_strength.gltf"] = d.gltf()

    # Lights: point, spot, directional; TRS and matrix nodes in a tree;
    # sensors by name and by extras.
    d = box_doc()
    d.use("KHR_lights_punctual")
    d.j["extensions"] = {"KHR_lights_punctual": {"lights": [
        {"type": "point", "name": "bulb", "intensity": 100,
         "color": [1, 0.9, 0.8], "range": 10},
        {"type": "spot", "name": "spot", "intensity": 500,
         "spot": {"innerConeAngle": 0.2, "outerConeAngle": 0.6}},
        {"type": "directional", "intensity": 1000}]}}
    lights = [d.node(name="bulb", translation=[1, 1.5, 1],
                     extensions={"KHR_lights_punctual": {"light": 0}}),
              d.node(name="spot", rotation=[-0.7071068, 0, 0, 0.7071068],
                     translation=[0.5, 1.8, 0.5],
                     extensions={"KHR_lights_punctual": {"light": 1}}),
              d.node(name="sun", matrix=[1, 0, 0, 0, 0, 0, -1, 0, 0, 1, 0,
                                         0, 0, 5, 0, 1],
                     extensions={"KHR_lights_punctual": {"light": 2}})]
    # Names beyond ASCII: notes and messages quote (and cut) them.
    d.j["materials"][0]["name"] = "W\u00e4nde \u00d8 " * 12
    sensors = [d.node(name="sensor:B\u00fcro", translation=[1, 0.8, 1]),
               d.node(name="wall probe", translation=[0.01, 1, 1],
                      rotation=[0, 0, -0.7071068, 0.7071068],
                      extras={"luxrad_sensor": "wall"})]
    group = d.node(name="Leuchten \u2014 " * 8, children=lights + sensors,
                   scale=[1, 1, 1], translation=[0, 0, 0])
    d.j["scenes"][0]["nodes"].append(group)
    out["lights_sensors.gltf"] = d.gltf()

    # Luminaires: photometric files packed as bufferViews.
    for name, fname, ext in [("luminaire_ies.glb", "cosine_1000lm.ies",
                              "glb"),
                             ("luminaire_ldt.gltf", "cosine_1600lm.ldt",
                              "gltf")]:
        with open(os.path.join(ROOT, "tests", "data", "photometry",
                               fname), "rb") as f:
            data = f.read()
        d = box_doc()
        d.use("KHR_lights_punctual")
        d.j["extensions"] = {"KHR_lights_punctual": {"lights": [
            {"type": "point", "name": "downlight", "intensity": 80}]}}
        v = d.view(data)
        d.j["scenes"][0]["nodes"].append(d.node(
            name="downlight", translation=[1, 1.9, 1],
            rotation=[0, 0.3826834, 0, 0.9238795],
            extensions={"KHR_lights_punctual": {"light": 0}},
            extras={"luxrad_photometry": {"bufferView": v, "name": fname}}))
        out[name] = d.glb() if ext == "glb" else d.gltf()
    return out


# ------------------------------------------------------------ requests

def args_seeds():
    pts = [[0, 0, 0, 0, 1, 0], [1.5, 0.8, 2, 0, 0, 1]]
    reqs = {
        "hello.json": {"cmd": "hello", "id": 1, "version": 1,
                       "token": "s3cret", "client": "luxrad/0.1"},
        "job_create.json": {
            "cmd": "job.create", "id": "a", "scene": 1, "solver": "rmb",
            "name": "office",
            "options": {"accuracy": 0.02, "eps": 1e-3, "oracle": "bf",
                        "variation": 0.4, "min_edge_rel": 0.01,
                        "mesh_edge_rel": 0.1, "clustering": False,
                        "store": "minimal", "study": True, "threads": 2,
                        "rcv_samples": 4, "vis_samples": 8,
                        "query_tol": 0.02, "tol": 0.002,
                        "max_iterations": 50}},
        "job_create_bad.json": {"cmd": "job.create", "scene": -1,
                                "solver": "radiosity",
                                "options": {"eps": "small", "threads": 1.5,
                                            "oracle": 3, "colour": 1}},
        "job_run.json": {"cmd": "job.run", "id": 7, "job": 3,
                         "iterations": 5, "converge": False,
                         "seconds": 2.5},
        "job_set.json": {"cmd": "job.set", "job": 3, "eps": 5e-4},
        "query_points.json": {"cmd": "query.points", "job": 3,
                              "points": pts},
        "query_points_bad.json": {"cmd": "query.points", "job": 3,
                                  "points": [[0, 0, 0, 0, 0, 0],
                                             [1, 2, 3], "x", [1e308] * 6]},
        "query_grid.json": {"cmd": "query.grid", "job": 3,
                            "origin": [0, 0.8, 0], "u": [4, 0, 0],
                            "v": [0, 0, 3], "normal": [0, 1, 0],
                            "spacing": 0.25, "points": True},
        "query_node.json": {"cmd": "query.node", "job": 3, "node": "desk",
                            "spacing": 0.1},
        "sensor_add.json": {"cmd": "sensor.add", "job": 3, "name": "desk",
                            "point": [1, 0.8, 1], "normal": [0, 1, 0]},
        "export.json": {"cmd": "export", "job": 3, "format": "glb"},
        "scene_upload.json": {"cmd": "scene.upload", "name": "box",
                              "bytes": 1234},
        "addresses.json": {"connect": "tcp:127.0.0.1:7420",
                           "listen": "[::1]:0", "unix": "unix:/run/l.sock",
                           "v6": "fe80::1", "host": "localhost"},
        "points_lines.json": {"a": "0 0 0 0 0 1 # desk",
                              "b": "1e3 -2 .5 0 -1 0", "c": "# only",
                              "d": "1 2 3 nan 0 1"},
        "edges.json": {"version": 18446744073709551615, "job": -0.0,
                       "eps": 1e308, "seconds": -1e-320, "iterations":
                       9223372036854775807, "converge": None,
                       "point": [1, 2, 3, 4], "normal": [], "u": {},
                       "name": "", "token": "\u00e9\u20ac"},
    }
    out = {k: dumps(v) for k, v in reqs.items()}
    out["array.json"] = dumps([1, {"cmd": "status"}])
    out["string.json"] = dumps("hello")
    out["number.json"] = "42"
    return out


# ------------------------------------------------------------- frames

def frame(header, payload=None):
    if payload is not None:
        header = dict(header, bytes=len(payload))
    return dumps(header).encode() + b"\n" + (payload or b"")


def frame_seeds(scene):
    hello = frame({"cmd": "hello", "id": 1, "version": 1,
                   "client": "fuzz"})
    out = {
        "hello.bin": hello,
        "session.bin": hello + frame({"cmd": "status", "id": 2}) +
        frame({"cmd": "scene.list", "id": 3}) +
        frame({"cmd": "job.create", "id": 4, "scene": 1, "solver": "hr",
               "options": {"eps": 1e-3}}) +
        frame({"cmd": "job.run", "id": 5, "job": 1, "iterations": 2}) +
        frame({"cmd": "subscribe", "id": 6, "job": 1}) +
        frame({"cmd": "shutdown", "id": 7}),
        "upload.bin": hello + frame({"cmd": "scene.upload", "id": 2,
                                     "name": "box"}, scene) +
        frame({"cmd": "scene.info", "id": 3, "scene": 1}),
        "upload_empty.bin": hello + frame({"cmd": "scene.upload",
                                           "id": 2}, b""),
        "upload_short.bin": hello + b'{"cmd":"scene.upload","bytes":100}\n' +
        b"glTF\x02\x00\x00\x00",
        "upload_huge.bin": hello +
        b'{"cmd":"scene.upload","bytes":2000000000}\n',
        "payload_wrong_cmd.bin": hello + frame({"cmd": "status"}, b"xyz") +
        frame({"cmd": "status", "id": 9}),
        "bytes_bad.bin": hello + b'{"cmd":"scene.upload","bytes":-1}\n',
        "bytes_real.bin": hello + b'{"cmd":"scene.upload","bytes":1.5}\n',
        "bytes_string.bin": hello + b'{"cmd":"scene.upload","bytes":"3"}\n',
        "no_hello.bin": frame({"cmd": "status", "id": 1}) + hello,
        "payload_before_hello.bin": frame({"cmd": "scene.upload"}, b"ab"),
        "hello_bad_version.bin": frame({"cmd": "hello", "version": 2}),
        "hello_no_version.bin": frame({"cmd": "hello", "id": [1]}) + hello,
        "hello_twice.bin": hello + hello,
        "unknown_cmd.bin": hello + frame({"cmd": "job.explode",
                                          "id": {"a": 1}}) +
        frame({"cmd": "\u00e9" * 40, "id": None}),
        "not_object.bin": b"[1,2,3]\n",
        "not_json.bin": b"{\"cmd\":\"hello\",\n",
        "duplicate_key.bin": b'{"cmd":"hello","cmd":"hello","version":1}\n',
        "crlf.bin": b'{"cmd":"hello","version":1}\r\n'
        b'{"cmd":"status"}\r\n',
        "long_line.bin": frame({"cmd": "hello", "version": 1,
                                "client": "x" * 80}),
        "partial.bin": hello + b'{"cmd":"status","id":',
        "replies.bin": frame({"id": 1, "ok": True, "version": 1}) +
        frame({"id": 2, "ok": False, "error": {"code": "not_found",
                                               "message": "no scene 9"}}) +
        frame({"event": "iteration", "job": 1, "iteration": 3}) +
        frame({"id": 3, "ok": False, "error": {"code": "teapot"}}) +
        frame({"id": 4, "ok": True}, b"glTF....") +
        frame({"ok": "yes"}),
    }
    return out


def main():
    out_dir = sys.argv[1] if len(sys.argv) > 1 else os.path.join(HERE,
                                                                 "corpus")
    gl = gltf_seeds()
    for name, data in gl.items():
        write(os.path.join(out_dir, "gltf", name), data)
    for name, data in args_seeds().items():
        write(os.path.join(out_dir, "args", name), data)
    for name, data in frame_seeds(gl["box.glb"]).items():
        write(os.path.join(out_dir, "frame", name), data)
    total = sum(os.path.getsize(os.path.join(dp, f))
                for dp, _, fs in os.walk(out_dir) for f in fs)
    print("make_corpus.py: %d files, %d bytes in %s" % (
        len(gl) + len(args_seeds()) + len(frame_seeds(b"")), total, out_dir))


if __name__ == "__main__":
    main()
