#!/usr/bin/python3
"""lamp_scene.py -- the luminaire tests' scene: a black 20 m floor (y = 0,
facing up) and a point light node "lamp" 3 m above it, aimed down (local
-Z to -Y), glTF intensity 50 cd.

Usage: lamp_scene.py OUT.gltf|OUT.glb [PHOTOMETRIC_FILE]
With PHOTOMETRIC_FILE, the lamp's node names it in its extras
(luxrad_photometry), a path beside OUT.gltf.  OUT.glb: a GLB, the
buffer in its binary chunk.
"""
import base64
import json
import struct
import sys

v = [-10, 0, -10, -10, 0, 10, 10, 0, 10, -10, 0, -10, 10, 0, 10, 10, 0, -10]
buf = struct.pack("<18f", *v)
lamp = {"name": "lamp", "translation": [0, 3, 0],
        "rotation": [-0.70710678, 0, 0, 0.70710678],
        "extensions": {"KHR_lights_punctual": {"light": 0}}}
if len(sys.argv) > 2:
    lamp["extras"] = {"luxrad_photometry": sys.argv[2]}
doc = {
    "asset": {"version": "2.0"}, "scene": 0,
    "extensionsUsed": ["KHR_lights_punctual"],
    "extensions": {"KHR_lights_punctual": {"lights": [
        {"type": "point", "intensity": 50, "color": [1, 1, 1]}]}},
    "scenes": [{"nodes": [0, 1]}],
    "nodes": [{"name": "floor", "mesh": 0}, lamp],
    "meshes": [{"primitives": [{"attributes": {"POSITION": 0},
                                "material": 0}]}],
    "materials": [{"pbrMetallicRoughness": {
        "baseColorFactor": [0, 0, 0, 1]}}],
    "accessors": [{"bufferView": 0, "componentType": 5126, "count": 6,
                   "type": "VEC3", "min": [-10, 0, -10],
                   "max": [10, 0, 10]}],
    "bufferViews": [{"buffer": 0, "byteLength": len(buf)}],
    "buffers": [{"byteLength": len(buf), "uri":
                 "data:application/octet-stream;base64," +
                 base64.b64encode(buf).decode()}]}
if sys.argv[1].endswith(".glb"):
    doc["buffers"] = [{"byteLength": len(buf)}]
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    body = (struct.pack("<II", len(text), 0x4E4F534A) + text +
            struct.pack("<II", len(buf), 0x004E4942) + buf)
    with open(sys.argv[1], "wb") as f:
        f.write(struct.pack("<III", 0x46546C67, 2, 12 + len(body)) + body)
else:
    with open(sys.argv[1], "w") as f:
        json.dump(doc, f)
