#!/usr/bin/env python3
"""Write a large-mesh variant of the shared Cornell box for the renderer benchmark.

The two boxes of <shared>/tools/mitsuba_ref/cornell.gltf are replaced by one bumpy sphere,
a latitude-longitude grid of N_U x N_V quads (2 N_U (N_V - 1) triangles once the
degenerate ones at the poles are dropped, at least --triangles, 10^6 by default), radius
r(theta, phi) = R (1 + 0.04 sin(24 theta) sin(24 phi)) so that neighbouring triangles differ
and the BVH, not a smooth silhouette, does the work. Material "white" of the box (spectral
reflectance in extras, read by both renderers). Vertex normals are the normalised sums of the
adjacent face normals. One .gltf + one .bin (the box's own buffer first, then the sphere).

usage: make_mesh_scene.py CORNELL.gltf OUT.gltf [--triangles 1000000]
"""
import argparse
import json
import os

import numpy as np


def sphere(n_u, n_v, centre, radius):
    theta = np.linspace(0.0, np.pi, n_v + 1)  # pole to pole
    phi = np.linspace(0.0, 2.0 * np.pi, n_u + 1)[:-1]  # seam closed by index wrap
    t, p = np.meshgrid(theta, phi, indexing="ij")
    r = radius * (1.0 + 0.04 * np.sin(24.0 * t) * np.sin(24.0 * p))
    pos = np.stack(
        [r * np.sin(t) * np.cos(p), r * np.cos(t), r * np.sin(t) * np.sin(p)], axis=-1
    ).reshape(-1, 3) + np.asarray(centre)
    i = np.arange(n_v)[:, None]
    j = np.arange(n_u)[None, :]
    a = i * n_u + j
    b = i * n_u + (j + 1) % n_u
    c = (i + 1) * n_u + j
    d = (i + 1) * n_u + (j + 1) % n_u
    # counter-clockwise seen from outside (outward normals)
    tri = np.concatenate(
        [np.stack([a, b, c], -1).reshape(-1, 3), np.stack([b, d, c], -1).reshape(-1, 3)]
    )
    v0, v1, v2 = pos[tri[:, 0]], pos[tri[:, 1]], pos[tri[:, 2]]
    fn = np.cross(v1 - v0, v2 - v0)
    area = np.linalg.norm(fn, axis=1)
    tri, fn = tri[area > 1e-14], fn[area > 1e-14]  # the pole rows' degenerate triangles
    nrm = np.zeros_like(pos)
    for k in range(3):
        np.add.at(nrm, tri[:, k], fn)
    out = pos - np.asarray(centre)
    flip = np.einsum("ij,ij->i", nrm, out) < 0.0
    if flip.mean() > 0.5:  # wound inwards: reverse
        tri = tri[:, [0, 2, 1]]
        nrm = -nrm
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-30)
    return pos.astype(np.float32), nrm.astype(np.float32), tri.astype(np.uint32)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("cornell")
    ap.add_argument("out")
    ap.add_argument("--triangles", type=int, default=1_000_000)
    a = ap.parse_args()
    doc = json.load(open(a.cornell))
    base = os.path.dirname(os.path.abspath(a.cornell))
    (buf0,) = doc["buffers"]
    data = bytearray(open(os.path.join(base, buf0["uri"]), "rb").read())
    n_v = max(4, int(round((a.triangles / 4.0) ** 0.5)))
    # the two pole rows lose one triangle per quad (degenerate), so 2 n_u (n_v - 1) remain
    n_u = max(8, -(-a.triangles // (2 * (n_v - 1))))
    pos, nrm, tri = sphere(n_u, n_v, (0.0, 0.6, 0.0), 0.55)

    def add(arr, target, ctype, typ, minmax=False):
        while len(data) % 4:
            data.append(0)
        off = len(data)
        raw = arr.tobytes()
        data.extend(raw)
        doc["bufferViews"].append(
            {"buffer": 0, "byteOffset": off, "byteLength": len(raw), "target": target}
        )
        acc = {
            "bufferView": len(doc["bufferViews"]) - 1,
            "componentType": ctype,
            "count": int(arr.shape[0]) if typ != "SCALAR" else int(arr.size),
            "type": typ,
        }
        if minmax:
            acc["min"] = [float(x) for x in arr.min(axis=0)]
            acc["max"] = [float(x) for x in arr.max(axis=0)]
        doc["accessors"].append(acc)
        return len(doc["accessors"]) - 1

    ip = add(pos, 34962, 5126, "VEC3", minmax=True)
    inn = add(nrm, 34962, 5126, "VEC3")
    ii = add(tri.reshape(-1), 34963, 5125, "SCALAR")
    white = [m["name"] for m in doc["materials"]].index("white")
    doc["meshes"].append(
        {
            "name": "bumpy_sphere",
            "primitives": [
                {"attributes": {"POSITION": ip, "NORMAL": inn}, "indices": ii, "material": white, "mode": 4}
            ],
        }
    )
    keep = [k for k, n in enumerate(doc["nodes"]) if n.get("name") not in ("short_box", "tall_box")]
    doc["nodes"].append({"name": "bumpy_sphere", "mesh": len(doc["meshes"]) - 1})
    doc["scenes"][doc.get("scene", 0)]["nodes"] = keep + [len(doc["nodes"]) - 1]
    bin_name = os.path.splitext(os.path.basename(a.out))[0] + ".bin"
    doc["buffers"] = [{"byteLength": len(data), "uri": bin_name}]
    open(os.path.join(os.path.dirname(os.path.abspath(a.out)), bin_name), "wb").write(bytes(data))
    json.dump(doc, open(a.out, "w"))
    print(json.dumps({"out": a.out, "sphere_triangles": int(tri.shape[0]), "n_u": n_u, "n_v": n_v}))


if __name__ == "__main__":
    main()
