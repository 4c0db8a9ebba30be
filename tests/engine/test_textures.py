#!/usr/bin/python3
"""test_textures.py -- textured reflectance against an independent reading.

luxrad gives each polygon of a textured material baseColorFactor x the mean
of its base colour texture under the polygon (daemon/sceneio/texture.c:
exact box integration of the texels, C, libpng/libjpeg).  This test reads
the same documents with other code -- Python's json, Pillow to decode the
images, numpy to sample each triangle at random points -- and compares
that estimate with the reflectance luxrad-solve --polygons reports for
every textured polygon.

Scenes: ones made here (a checker PNG with repeat, mirrored repeat and
clamp, KHR_texture_transform, a JPEG, a uniform texture whose mean is
known exactly) and the real Blender exports in ../shared/scenes/real/.

Usage: test_textures.py LUXRAD_SOLVE SOURCE_DIR
"""
import base64
import csv
import io
import json
import math
import os
import struct
import subprocess
import sys
import tempfile

import numpy as np
from PIL import Image

SAMPLES = 20000  # random points per source triangle
TOL = 0.012  # |luxrad - estimate|, reflectance units (3.4 sigma worst)
RNG = np.random.default_rng(12345)

failures = []


def check(ok, what):
    print(("ok   " if ok else "FAIL ") + what)
    if not ok:
        failures.append(what)


# ------------------------------------------------------------ glTF reading

def quat_matrix(q):
    x, y, z, w = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def local_matrix(node):
    if "matrix" in node:
        return np.array(node["matrix"], dtype=float).reshape(4, 4).T
    m = np.eye(4)
    s = np.diag(node.get("scale", [1, 1, 1]))
    r = quat_matrix(node.get("rotation", [0, 0, 0, 1]))
    m[:3, :3] = r @ s
    m[:3, 3] = node.get("translation", [0, 0, 0])
    return m


class Doc:
    """A .gltf and the files beside it, or a .glb."""

    def __init__(self, path):
        self.dir = os.path.dirname(path)
        raw = open(path, "rb").read()
        self.bin = None
        if raw[:4] == b"glTF":
            n = struct.unpack_from("<I", raw, 12)[0]
            self.j = json.loads(raw[20:20 + n])
            self.bin = raw[20 + n + 8:]
        else:
            self.j = json.loads(raw)
        self.buffers = [self.load_uri(b.get("uri")) for b in
                        self.j.get("buffers", [])]

    def load_uri(self, uri):
        if uri is None:
            return self.bin
        if uri.startswith("data:"):
            return base64.b64decode(uri.split(",", 1)[1])
        return open(os.path.join(self.dir, uri), "rb").read()

    def view(self, vi):
        v = self.j["bufferViews"][vi]
        b = self.buffers[v["buffer"]]
        o = v.get("byteOffset", 0)
        return b[o:o + v["byteLength"]], v.get("byteStride", 0)

    def accessor(self, ai):
        a = self.j["accessors"][ai]
        comps = {"SCALAR": 1, "VEC2": 2, "VEC3": 3}[a["type"]]
        dt = {5126: np.float32, 5125: np.uint32, 5123: np.uint16,
              5121: np.uint8}[a["componentType"]]
        data, stride = self.view(a["bufferView"])
        item = np.dtype(dt).itemsize * comps
        stride = stride or item
        off = a.get("byteOffset", 0)
        out = np.empty((a["count"], comps), dtype=float)
        for i in range(a["count"]):
            out[i] = np.frombuffer(data, dtype=dt, count=comps,
                                   offset=off + i * stride)
        if a.get("normalized"):
            out /= float(np.iinfo(dt).max)
        return out

    def image_linear(self, ii):
        img = self.j["images"][ii]
        if "bufferView" in img:
            data = bytes(self.view(img["bufferView"])[0])
        else:
            data = self.load_uri(img["uri"])
        px = np.asarray(Image.open(io.BytesIO(data)).convert("RGB"),
                        dtype=float) / 255.0
        return np.where(px <= 0.04045, px / 12.92,
                        ((px + 0.055) / 1.055) ** 2.4)

    def triangles(self):
        """(node name, world triangle, uv triangle or None, material)"""
        j = self.j
        sc = j.get("scene", 0)
        roots = j["scenes"][sc]["nodes"] if "scenes" in j else []
        stack = [(r, np.eye(4)) for r in roots]
        while stack:
            ni, parent = stack.pop()
            node = j["nodes"][ni]
            world = parent @ local_matrix(node)
            stack += [(c, world) for c in node.get("children", [])]
            if "mesh" not in node:
                continue
            mesh = j["meshes"][node["mesh"]]
            name = node.get("name") or mesh.get("name") or "node%d" % ni
            for prim in mesh["primitives"]:
                if prim.get("mode", 4) != 4:
                    continue
                mi = prim.get("material", -1)
                mat = j["materials"][mi] if mi >= 0 else {}
                ti = mat.get("pbrMetallicRoughness", {}).get(
                    "baseColorTexture")
                pos = self.accessor(prim["attributes"]["POSITION"])
                pos = (world @ np.c_[pos, np.ones(len(pos))].T).T[:, :3]
                idx = (self.accessor(prim["indices"])[:, 0].astype(int)
                       if "indices" in prim else np.arange(len(pos)))
                uv = None
                if ti is not None:
                    tc = ti.get("extensions", {}).get(
                        "KHR_texture_transform", {}).get(
                        "texCoord", ti.get("texCoord", 0))
                    uv = self.accessor(prim["attributes"]["TEXCOORD_%d" % tc])
                for t in range(len(idx) // 3):
                    c = idx[3 * t:3 * t + 3]
                    yield name, pos[c], None if uv is None else uv[c], mat


def texture_mean(doc, mat, uv3, cache):
    """Mean linear RGB over the UV triangle by random points."""
    pbr = mat["pbrMetallicRoughness"]
    ti = pbr["baseColorTexture"]
    tex = doc.j["textures"][ti["index"]]
    if tex["source"] not in cache:
        cache[tex["source"]] = doc.image_linear(tex["source"])
    img = cache[tex["source"]]
    h, w, _ = img.shape
    samp = doc.j.get("samplers", [{}])[tex["sampler"]] \
        if "sampler" in tex else {}
    tt = ti.get("extensions", {}).get("KHR_texture_transform", {})
    ox, oy = tt.get("offset", [0, 0])
    sx, sy = tt.get("scale", [1, 1])
    r = tt.get("rotation", 0)
    a, b = RNG.random(SAMPLES), RNG.random(SAMPLES)
    flip = a + b > 1
    a[flip], b[flip] = 1 - a[flip], 1 - b[flip]
    p = uv3[0] + np.outer(a, uv3[1] - uv3[0]) + np.outer(b, uv3[2] - uv3[0])
    u, v = p[:, 0] * sx, p[:, 1] * sy
    u, v = (math.cos(r) * u + math.sin(r) * v + ox,
            -math.sin(r) * u + math.cos(r) * v + oy)

    def wrap(x, n, mode):
        i = np.floor(x * n).astype(np.int64)
        if mode == 33071:
            return np.clip(i, 0, n - 1)
        if mode == 33648:
            m = np.mod(i, 2 * n)
            return np.where(m < n, m, 2 * n - 1 - m)
        return np.mod(i, n)
    x = wrap(u, w, samp.get("wrapS", 10497))
    y = wrap(v, h, samp.get("wrapT", 10497))
    return img[y, x].mean(axis=0)


# ------------------------------------------------------------ comparison

def luxrad_polygons(solve, scene, tmp):
    out = os.path.join(tmp, "polygons.csv")
    subprocess.run([solve, scene, "--polygons", out, "--iterations", "1"],
                   check=True, stdout=subprocess.DEVNULL)
    rows = list(csv.DictReader(open(out)))
    for r in rows:
        n = int(r["corners"])
        r["P"] = np.array([[float(r["%s%d" % (c, k)]) for c in "xyz"]
                           for k in range(n)])
        r["rho"] = np.array([float(r["rho_" + c]) for c in "rgb"])
    return rows


def inside(poly, c):
    """Is point c on polygon poly (3 or 4 corners, quads parallelograms)?"""
    p0, e1, e2 = poly[0], poly[1] - poly[0], poly[-1] - poly[0]
    n = np.cross(e1, e2)
    if abs(np.dot(c - p0, n)) > 1e-4 * np.linalg.norm(n):
        return False
    m = np.array([e1, e2]).T
    (s, t), *_ = np.linalg.lstsq(m, c - p0, rcond=None)
    e = -1e-6
    if len(poly) == 4:
        return s >= e and t >= e and s <= 1 - e and t <= 1 - e
    return s >= e and t >= e and s + t <= 1 - e


def compare(solve, scene, label, tmp, expect_exact=None):
    doc = Doc(scene)
    cache, src = {}, {}
    for name, tri, uv, mat in doc.triangles():
        if uv is None:
            continue
        mean = texture_mean(doc, mat, uv, cache)
        f = np.array(mat["pbrMetallicRoughness"].get(
            "baseColorFactor", [1, 1, 1, 1])[:3])
        area = 0.5 * np.linalg.norm(np.cross(tri[1] - tri[0],
                                             tri[2] - tri[0]))
        src.setdefault(name, []).append((tri.mean(axis=0), area,
                                         np.minimum(f * mean, 0.999)))
    polys = [p for p in luxrad_polygons(solve, scene, tmp)
             if p["node"] in src]
    worst, matched, covered = 0.0, 0, set()
    for p in polys:
        hits = [(k, a, rho) for k, (c, a, rho) in enumerate(src[p["node"]])
                if inside(p["P"], c)]
        if not hits:  # an untextured primitive of the same node
            continue
        matched += 1
        covered |= {(p["node"], k) for k, _, _ in hits}
        est = sum(a * rho for _, a, rho in hits) / \
            sum(a for _, a, _ in hits)
        if expect_exact is not None:
            est = np.array(expect_exact)
        worst = max(worst, float(np.abs(p["rho"] - est).max()))
    ntex = sum(len(v) for v in src.values())
    check(matched > 0 and len(covered) == ntex,
          "%s: %d polygons cover all %d textured source triangles "
          "(covered: %d)" % (label, matched, ntex, len(covered)))
    tol = 2e-6 if expect_exact is not None else TOL
    check(worst <= tol, "%s: worst reflectance difference %.4g (<= %g)"
          % (label, worst, tol))


# ------------------------------------------------------------ scenes made here

def image_bytes(pixels, fmt):
    buf = io.BytesIO()
    Image.fromarray(pixels.astype(np.uint8), "RGB").save(
        buf, fmt, **({"quality": 95} if fmt == "JPEG" else {}))
    return buf.getvalue()


def checker(n, cell, a, b):
    y, x = np.mgrid[0:n, 0:n]
    on = ((x // cell + y // cell) % 2 == 0)[..., None]
    return np.where(on, np.array(a), np.array(b))


def made_scene(path, img, mime, uv_scale, sampler=None, transform=None,
               factor=(1, 1, 1)):
    """A 4 m floor of 4 x 4 quads (32 triangles) under an emitter."""
    pos, uv, idx = [], [], []
    n = 4
    for j in range(n + 1):
        for i in range(n + 1):
            pos.append((i * 4.0 / n, 0.0, j * 4.0 / n))
            uv.append((i * uv_scale / n + 0.13, j * uv_scale * 0.7 / n))
    for j in range(n):
        for i in range(n):
            a = j * (n + 1) + i
            idx += [a, a + n + 1, a + 1, a + 1, a + n + 1, a + n + 2]
    lamp = [(1.5, 3, 1.5), (2.5, 3, 1.5), (2.5, 3, 2.5), (1.5, 3, 2.5)]
    blob = b"".join(struct.pack("<3f", *p) for p in pos + lamp)
    off_uv = len(blob)
    blob += b"".join(struct.pack("<2f", *t) for t in uv)
    off_idx = len(blob)
    blob += struct.pack("<%dI" % len(idx), *idx)
    off_lidx = len(blob)
    blob += struct.pack("<6I", 0, 1, 2, 0, 2, 3)
    off_img = len(blob)
    blob += img
    while len(blob) % 4:
        blob += b"\0"
    np_ = len(pos)
    ti = {"index": 0}
    if transform:
        ti["extensions"] = {"KHR_texture_transform": transform}
    tex = {"source": 0}
    if sampler:
        tex["sampler"] = 0
    j = {
        "asset": {"version": "2.0"},
        "extensionsUsed": ["KHR_texture_transform"] if transform else [],
        "scene": 0, "scenes": [{"nodes": [0, 1]}],
        "nodes": [{"name": "floor", "mesh": 0}, {"name": "lamp", "mesh": 1}],
        "meshes": [
            {"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1},
                             "indices": 2, "material": 0}]},
            {"primitives": [{"attributes": {"POSITION": 3}, "indices": 4,
                             "material": 1}]}],
        "materials": [
            {"pbrMetallicRoughness": {"baseColorTexture": ti,
                                      "baseColorFactor": list(factor) + [1],
                                      "metallicFactor": 0}},
            {"emissiveFactor": [1, 1, 1],
             "pbrMetallicRoughness": {"baseColorFactor": [0, 0, 0, 1]}}],
        "textures": [tex],
        "images": [{"bufferView": 4, "mimeType": mime}],
        "samplers": [sampler] if sampler else [],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": np_,
             "type": "VEC3", "min": [0, 0, 0], "max": [4, 0, 4]},
            {"bufferView": 1, "componentType": 5126, "count": np_,
             "type": "VEC2"},
            {"bufferView": 2, "componentType": 5125, "count": len(idx),
             "type": "SCALAR"},
            {"bufferView": 0, "byteOffset": 12 * np_, "componentType": 5126,
             "count": 4, "type": "VEC3", "min": [1.5, 3, 1.5],
             "max": [2.5, 3, 2.5]},
            {"bufferView": 3, "componentType": 5125, "count": 6,
             "type": "SCALAR"}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": off_uv},
            {"buffer": 0, "byteOffset": off_uv,
             "byteLength": off_idx - off_uv},
            {"buffer": 0, "byteOffset": off_idx,
             "byteLength": off_lidx - off_idx},
            {"buffer": 0, "byteOffset": off_lidx, "byteLength": 24},
            {"buffer": 0, "byteOffset": off_img, "byteLength": len(img)}],
        "buffers": [{"byteLength": len(blob),
                     "uri": "data:application/octet-stream;base64," +
                     base64.b64encode(blob).decode()}],
    }
    if not j["samplers"]:
        del j["samplers"]
    with open(path, "w") as f:
        json.dump(j, f)


def main():
    solve, source = sys.argv[1], sys.argv[2]
    real = os.path.join(source, "..", "shared", "scenes", "real")
    dark, light = (30, 60, 90), (230, 200, 140)
    png = image_bytes(checker(64, 8, dark, light), "PNG")
    with tempfile.TemporaryDirectory() as tmp:
        cases = [
            ("repeat", png, "image/png", 3.7, None, None),
            ("mirrored", png, "image/png", 3.7,
             {"wrapS": 33648, "wrapT": 33648}, None),
            ("clamp", png, "image/png", 1.6,
             {"wrapS": 33071, "wrapT": 33071}, None),
            ("transform", png, "image/png", 1.0, None,
             {"offset": [0.3, -0.2], "rotation": 0.61,
              "scale": [2.5, 1.5]}),
            ("jpeg", image_bytes(checker(64, 8, dark, light), "JPEG"),
             "image/jpeg", 2.2, None, None),
        ]
        for label, img, mime, s, samp, tt in cases:
            path = os.path.join(tmp, label + ".gltf")
            made_scene(path, img, mime, s, samp, tt, (0.9, 0.8, 1.0))
            compare(solve, path, label, tmp)
        # A uniform texture: every polygon's reflectance is known exactly.
        grey = np.full((16, 16, 3), 128)
        path = os.path.join(tmp, "uniform.gltf")
        made_scene(path, image_bytes(grey, "PNG"), "image/png", 5.3,
                   None, None, (0.5, 1.0, 0.25))
        lin = ((128 / 255 + 0.055) / 1.055) ** 2.4
        compare(solve, path, "uniform", tmp,
                expect_exact=[0.5 * lin, lin, 0.25 * lin])
        # Damaged images: each loads with a note or is refused, never
        # crashes (the decoders see hostile bytes; CI runs this under
        # ASan).
        rng = np.random.default_rng(7)
        for label, img in (("png", png), ("jpeg", cases[4][1])):
            worst = 0
            for k in range(24):
                b = bytearray(img)
                if k % 3 == 2:
                    b = b[:int(rng.integers(8, len(b)))]
                else:
                    for _ in range(1 + k % 4):
                        at = int(rng.integers(0, len(b)))
                        b[at] ^= int(rng.integers(1, 256))
                path = os.path.join(tmp, "damaged.gltf")
                made_scene(path, bytes(b), "image/" + label, 2.0)
                rc = subprocess.run([solve, path, "--iterations", "1"],
                                    stdout=subprocess.DEVNULL,
                                    stderr=subprocess.DEVNULL).returncode
                worst = max(worst, rc if rc >= 0 else 128 - rc)
            check(worst <= 1, "damaged %s images: 24 load or are refused, "
                  "none crashes (worst exit %d)" % (label, worst))
        for d in ("BJS-2.79-Cycles-gltf", "BJS-2.80-Eevee-gltf"):
            folder = os.path.join(real, "vinc3r-cornellbox", d)
            if not os.path.isdir(folder):
                check(False, "%s: not found (../shared/ beside the "
                      "checkout)" % folder)
                continue
            gltf = [f for f in os.listdir(folder) if f.endswith(".gltf")]
            compare(solve, os.path.join(folder, gltf[0]), d, tmp)
    print("%d failure(s)" % len(failures))
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
