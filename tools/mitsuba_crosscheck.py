#!/usr/bin/env python3
"""Cross-check of `translucent truth` against Mitsuba 3 on one small scene.

Both render the same scene: a 20 mm cube of a homogeneous medium with an index-matched
boundary (eta = 1), an isotropic phase function on the reduced coefficients, one directional
light of irradiance 1 and one pinhole camera. Mitsuba uses `volpathmis` (spectral MIS),
max_depth -1 and Russian roulette pushed beyond any path's length, a `null` BSDF and the
`scalar_rgb` variant (no LLVM needed). Mitsuba samples positions inside each pixel (box filter)
where `truth` traces pixel centres, so the object means are compared over the pixels whose
3x3 neighbourhood lies inside the object in both images; Mitsuba's standard error comes from
two renders with different seeds, truth's from its noise.exr.

With `--environment`, the light is the shipped sky (assets/environments/sky.exr) instead: an
`envmap` in Mitsuba (whose direction convention the renderer follows), `[[lights]] kind =
"environment"` in `truth`; both draw environment directions by brightness.

Needs: `pip install mitsuba numpy` and a release build (`cargo build --release`).
Usage:   python3 tools/mitsuba_crosscheck.py [--material skin1] [--spp 256] [--size 64]
                                             [--environment]
Prints the object means, their difference in combined standard errors, and the relative RMS
difference after 4x4 binning with both noises removed. Exits 1 when the means differ by
more than 2 combined standard errors in any channel.
"""

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile

import numpy as np
import mitsuba as mi

PRESETS = {
    # sigma_s', sigma_a in 1/mm (Jensen et al. 2001), as in src/physics/material.rs.
    "skin1": ([0.74, 0.88, 1.01], [0.032, 0.17, 0.48]),
    "ketchup": ([0.18, 0.07, 0.03], [0.061, 0.97, 1.45]),
    "skimmilk": ([0.70, 1.22, 1.90], [0.0014, 0.0025, 0.0142]),
    "marble": ([2.19, 2.62, 3.00], [0.0021, 0.0041, 0.0071]),
}

CAMERA = ([45.0, 35.0, 60.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], 30.0)
LIGHT = [-0.5, -1.0, -0.3]  # direction of travel
HALF = 10.0  # mm: half the cube's edge


SKY = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "assets", "environments", "sky.exr")


def truth(binary, material, spp, size, out, environment):
    cam, tgt, up, fov = CAMERA
    light = (
        '[[lights]]\nkind = "environment"'
        if environment
        else f'[[lights]]\nkind = "directional"\ndirection = {LIGHT}'
    )
    scene = f"""
[mesh]
builtin = "box"
size = [{2 * HALF}, {2 * HALF}, {2 * HALF}]
segments = 8
[camera]
position = {cam}
target = {tgt}
up = {up}
fov_deg = {fov}
{light}
[material]
preset = "{material}"
eta = 1.0
[output]
width = {size}
height = {size}
"""
    path = os.path.join(out, "scene.toml")
    with open(path, "w") as f:
        f.write(scene)
    subprocess.run(
        [binary, "truth", path, "--spp", str(spp), "--out", out], check=True
    )
    img = np.array(mi.Bitmap(os.path.join(out, "truth.exr")), dtype=np.float64)
    noise = np.array(mi.Bitmap(os.path.join(out, "noise.exr")), dtype=np.float64)
    info = json.load(open(os.path.join(out, "truth.json")))
    return img, noise, info


def mitsuba(material, spp, size, seed, environment):
    sp, sa = PRESETS[material]
    sigma_t = [s + a for s, a in zip(sp, sa)]
    albedo = [s / t for s, t in zip(sp, sigma_t)]
    # Mitsuba checks RGB values as reflectances (at most 1): sigma_t goes in normalised, with
    # its largest channel as the medium's scale.
    scale = max(sigma_t)
    cam, tgt, up, fov = CAMERA
    scene = mi.load_dict(
        {
            "type": "scene",
            "integrator": {"type": "volpathmis", "max_depth": -1, "rr_depth": 1 << 30},
            "sensor": {
                "type": "perspective",
                "fov": fov,
                "fov_axis": "y",
                "to_world": mi.ScalarTransform4f().look_at(origin=cam, target=tgt, up=up),
                "film": {
                    "type": "hdrfilm",
                    "width": size,
                    "height": size,
                    "pixel_format": "rgba",
                    "rfilter": {"type": "box"},
                },
                "sampler": {"type": "independent", "sample_count": spp},
            },
            "light": (
                {"type": "envmap", "filename": os.path.abspath(SKY)}
                if environment
                else {
                    "type": "directional",
                    "direction": LIGHT,
                    "irradiance": {"type": "rgb", "value": [1.0, 1.0, 1.0]},
                }
            ),
            "cube": {
                "type": "cube",
                "to_world": mi.ScalarTransform4f().scale([HALF, HALF, HALF]),
                "bsdf": {"type": "null"},
                "interior": {
                    "type": "homogeneous",
                    "albedo": {"type": "rgb", "value": albedo},
                    "sigma_t": {"type": "rgb", "value": [t / scale for t in sigma_t]},
                    "scale": scale,
                    "phase": {"type": "isotropic"},
                },
            },
        }
    )
    return np.array(mi.render(scene, seed=seed), dtype=np.float64)


def interior(alpha):
    """Pixels whose 3x3 neighbourhood is fully covered."""
    inside = alpha > 0.999
    m = inside.copy()
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            m &= np.roll(np.roll(inside, dy, 0), dx, 1)
    m[0, :] = m[-1, :] = m[:, 0] = m[:, -1] = False
    return m


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--material", default="skin1", choices=sorted(PRESETS))
    p.add_argument("--spp", type=int, default=256)
    p.add_argument("--size", type=int, default=64)
    p.add_argument("--binary", default="target/release/translucent")
    p.add_argument("--environment", action="store_true", help="light by the shipped sky")
    a = p.parse_args()
    mi.set_variant("scalar_rgb")
    out = tempfile.mkdtemp(prefix="crosscheck-")
    t, t_noise, info = truth(a.binary, a.material, a.spp, a.size, out, a.environment)
    ma = mitsuba(a.material, a.spp // 2, a.size, 1, a.environment)
    mb = mitsuba(a.material, a.spp // 2, a.size, 2, a.environment)
    m = 0.5 * (ma + mb)
    m_noise = 0.5 * np.abs(ma - mb)
    # Orientation: Mitsuba's image against truth's and its mirror image; keep the closer.
    mask = interior(t[..., 3]) & interior(m[..., 3])
    flipped = m[:, ::-1]
    mask_f = interior(t[..., 3]) & interior(flipped[..., 3])
    d = np.sum((m[..., :3] - t[..., :3])[mask] ** 2) / max(mask.sum(), 1)
    d_f = np.sum((flipped[..., :3] - t[..., :3])[mask_f] ** 2) / max(mask_f.sum(), 1)
    if d_f < d:
        m, m_noise, mask = flipped, m_noise[:, ::-1], mask_f
    n = mask.sum()
    light = "the shipped sky" if a.environment else "a directional light"
    print(f"material {a.material} under {light}, {a.size}x{a.size}, {a.spp} spp each, {n} interior pixels")
    print(f"truth: {info['seconds']:.1f} s, {info['events_per_second'] / 1e6:.2f} M collisions/s")
    worst = 0.0
    for c, name in enumerate(["red", "green", "blue"]):
        mt, mm = t[..., c][mask].mean(), m[..., c][mask].mean()
        se_t = math.sqrt(np.sum(t_noise[..., c][mask] ** 2)) / n
        se_m = math.sqrt(np.sum(m_noise[..., c][mask] ** 2)) / n
        se = math.hypot(se_t, se_m)
        z = (mt - mm) / se
        worst = max(worst, abs(z))
        print(
            f"{name:>5}: truth {mt:.5e} +- {se_t:.1e}, mitsuba {mm:.5e} +- {se_m:.1e}: "
            f"difference {100 * (mt / mm - 1):+.2f} % = {z:+.2f} standard errors"
        )
    # Per-region agreement: 4x4 bins inside both, both noises removed.
    h, w = mask.shape
    k = 4
    num = np.zeros(3)
    den = np.zeros(3)
    var = np.zeros(3)
    for by in range(h // k):
        for bx in range(w // k):
            sl = (slice(by * k, by * k + k), slice(bx * k, bx * k + k))
            if not mask[sl].all():
                continue
            for c in range(3):
                bt, bm = t[sl][..., c].mean(), m[sl][..., c].mean()
                num[c] += (bt - bm) ** 2
                den[c] += bm**2
                var[c] += (np.sum(t_noise[sl][..., c] ** 2) + np.sum(m_noise[sl][..., c] ** 2)) / k**4
    rel = np.sqrt(np.maximum(num - var, 0) / den)
    print(
        "4x4 bins: relative RMS difference with both noises removed "
        + " / ".join(f"{100 * r:.2f}" for r in rel)
        + " % (measured "
        + " / ".join(f"{100 * r:.2f}" for r in np.sqrt(num / den))
        + " %)"
    )
    print("agree" if worst < 2.0 else "DISAGREE", f"(worst channel {worst:.2f} standard errors)")
    sys.exit(0 if worst < 2.0 else 1)


if __name__ == "__main__":
    main()
