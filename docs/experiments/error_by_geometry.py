#!/usr/bin/env python3
"""Where a render of the bunny is off from a truth, by the geometry of the visible point.

    python3 docs/experiments/error_by_geometry.py OUT/render.exr TRUTH/truth.exr

OUT is a `translucent render` folder (its scene.toml gives the camera and the light), the
mesh is the builtin bunny (assets/bunny.obj, untransformed), the truth any EXR of the same
size. Each pixel's camera ray is cast against the mesh (numpy, the same pixel centres as the
renderer: the masks agree pixel for pixel); at the point it meets, with the mesh's smooth
normal n:
  - irradiance: max(n . l, 0), 0 where a ray towards the light meets the mesh;
  - view cosine: n . v;
  - concavity at 4 mm: the mean height of the surface around the point above its tangent
    plane (Gaussian weights of width 4 mm, by vertex area), over 4 mm: > 0 in a crease.
The 4x4 bins inside the object and not next to its silhouette are split into five equal
groups by each quantity; per group: render / truth (sums) and the group's part of the squared
relative RMS error (in 1e-4 of the truth's squared sum). Needs numpy and OpenEXR (pip
`OpenEXR`), about 30 s on 2 cores.
"""
import pathlib
import sys
import tomllib

import Imath
import numpy as np
import OpenEXR

ROOT = pathlib.Path(__file__).resolve().parents[2]


def load(path):
    f = OpenEXR.InputFile(str(path))
    dw = f.header()["dataWindow"]
    w, h = dw.max.x - dw.min.x + 1, dw.max.y - dw.min.y + 1
    pt = Imath.PixelType(Imath.PixelType.FLOAT)
    ch = [np.frombuffer(f.channel(c, pt), dtype=np.float32).reshape(h, w) for c in "RGBA"]
    return np.stack(ch, -1).astype(np.float64)


def mesh():
    v, f = [], []
    for line in open(ROOT / "assets" / "bunny.obj"):
        if line.startswith("v "):
            v.append([float(x) for x in line.split()[1:4]])
        elif line.startswith("f "):
            f.append([int(x.split("/")[0]) - 1 for x in line.split()[1:4]])
    v, f = np.array(v), np.array(f)
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    volume = np.einsum("ij,ij->i", v[f[:, 0]], np.cross(v[f[:, 1]], v[f[:, 2]])).sum()
    if volume < 0:
        fn = -fn
    n = np.zeros_like(v)
    area = np.zeros(len(v))
    for k in range(3):
        np.add.at(n, f[:, k], fn)
        np.add.at(area, f[:, k], np.linalg.norm(fn, axis=1) / 6)
    return v, f, n / np.linalg.norm(n, axis=1)[:, None], area


def cast(v, f, origins, dirs):
    """Nearest hit per ray: (t, triangle, u, v); t infinite where none."""
    a, e1, e2 = v[f[:, 0]], v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]
    out = [np.full(len(dirs), np.inf), np.zeros(len(dirs), int), np.zeros(len(dirs)), np.zeros(len(dirs))]
    for i in range(0, len(dirs), 1024):
        d, o = dirs[i : i + 1024], origins[i : i + 1024]
        p = np.cross(d[:, None, :], e2[None])
        det = np.einsum("ijk,jk->ij", p, e1)
        inv = 1 / np.where(np.abs(det) < 1e-12, 1e-12, det)
        t0 = o[:, None, :] - a[None]
        u = np.einsum("ijk,ijk->ij", p, t0) * inv
        q = np.cross(t0, e1[None])
        w = np.einsum("ik,ijk->ij", d, q) * inv
        t = np.einsum("jk,ijk->ij", e2, q) * inv
        ok = (u >= 0) & (w >= 0) & (u + w <= 1) & (t > 1e-3) & (np.abs(det) > 1e-12)
        t = np.where(ok, t, np.inf)
        j = t.argmin(1)
        r = np.arange(len(d))
        out[0][i : i + 1024], out[1][i : i + 1024] = t[r, j], j
        out[2][i : i + 1024], out[3][i : i + 1024] = u[r, j], w[r, j]
    return out


def camera_rays(scene, h, w):
    """The eye and the unit ray through each pixel centre of an h x w image, row by row (the
    renderer's pixel centres)."""
    cam = scene["camera"]
    eye, target = np.array(cam["position"]), np.array(cam["target"])
    fwd = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(fwd, cam["up"])
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    tan = np.tan(np.radians(cam["fov_deg"]) / 2)
    ys, xs = np.mgrid[0:h, 0:w]
    px, py = ((xs + 0.5) / w * 2 - 1) * tan * w / h, (1 - (ys + 0.5) / h * 2) * tan
    dirs = (fwd + px[..., None] * right + py[..., None] * up).reshape(-1, 3)
    return eye, dirs / np.linalg.norm(dirs, axis=1)[:, None]


def visible(scene, render, v, f, vn):
    """What each pixel of `render` sees: the camera rays (all pixels), which of them meet the
    mesh, and at those points the barycentrics, the triangle's corners, the point, the smooth
    normal, the unit direction towards the scene's first light and whether the mesh shadows it."""
    h, w = render.shape[:2]
    eye, dirs = camera_rays(scene, h, w)
    t, tri, bu, bv = cast(v, f, np.repeat(eye[None], len(dirs), 0), dirs)
    hit = np.isfinite(t)
    if (hit.reshape(h, w) != (render[..., 3] > 0)).any():
        sys.exit("the cast rays do not meet the mesh where the render covers it: another camera or mesh?")
    bary = np.stack([1 - bu - bv, bu, bv], 1)[hit]
    corners = f[tri[hit]]
    x = eye + dirs[hit] * t[hit][:, None]
    n = np.einsum("ij,ijk->ik", bary, vn[corners])
    n /= np.linalg.norm(n, axis=1)[:, None]
    light = -np.array(scene["lights"][0]["direction"], float)
    light /= np.linalg.norm(light)
    shadowed = np.isfinite(cast(v, f, x + n * 1e-3, np.repeat(light[None], len(x), 0))[0])
    return dirs, hit, bary, corners, x, n, light, shadowed


def main():
    render_path, truth_path = pathlib.Path(sys.argv[1]), sys.argv[2]
    scene = tomllib.loads((render_path.parent / "scene.toml").read_text())
    render, truth = load(render_path), load(truth_path)
    h, w = render.shape[:2]
    v, f, vn, varea = mesh()
    dirs, hit, bary, corners, x, n, light, shadowed = visible(scene, render, v, f, vn)
    d = v[None, :, :] - v[:, None, :]
    g = np.exp(-((np.linalg.norm(d, axis=2) / 4.0) ** 2)) * varea[None, :]
    concavity = (g * np.einsum("ijk,ik->ij", d, vn)).sum(1) / g.sum(1) / 4.0
    features = {
        "irradiance": np.clip(n @ light, 0, None) * ~shadowed,
        "view cosine": np.einsum("ij,ij->i", n, -dirs[hit]),
        "concavity": np.einsum("ij,ij->i", bary, concavity[corners]),
    }

    def bin4(a):
        return a.reshape(h // 4, 4, w // 4, 4, -1).sum((1, 3))

    inside = bin4(((render[..., 3] > 0) & (truth[..., 3] > 0))[..., None].astype(float))[..., 0] == 16
    edge = inside & ~(np.roll(inside, 1, 0) & np.roll(inside, -1, 0) & np.roll(inside, 1, 1) & np.roll(inside, -1, 1))
    keep = inside & ~edge
    rb, tb = bin4(render[..., :3])[keep], bin4(truth[..., :3])[keep]
    total = (tb**2).sum(0)
    print(f"{keep.sum()} interior bins: render / truth {np.round(rb.sum(0) / tb.sum(0), 3)}")
    for name, per_pixel in features.items():
        full = np.zeros(h * w)
        full[hit] = per_pixel
        q = (bin4(full.reshape(h, w)[..., None])[..., 0] / 16)[keep]
        edges = np.quantile(q, np.linspace(0, 1, 6))
        print(name)
        for lo, hi in zip(edges[:-1], edges[1:]):
            s = (q >= lo) & (q <= hi)
            ratio = rb[s].sum(0) / tb[s].sum(0)
            part = ((rb[s] - tb[s]) ** 2).sum(0) / total * 1e4
            print(f"  {lo:7.3f} - {hi:7.3f}: render / truth {np.round(ratio, 3)}, squared error {np.round(part, 1)}")


if __name__ == "__main__":
    main()
