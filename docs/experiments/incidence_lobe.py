"""What an exit lobe of orders >= 2 that follows the lamp's incidence would do to a render.

Usage: python3 docs/experiments/incidence_lobe.py OUT/render.exr SINGLE/render.exr DIR [deep]

OUT is a render of one of the truth bunnies (assets/scenes/truth/bunny-*.toml, its scene.toml
beside it); SINGLE the same scene's single scattering alone (docs/experiments/single-only.patch,
`TL_EXPERIMENT_SINGLE_ONLY=1 translucent render S --model halfspace-single --no-cache`). Each
pixel's ray is cast against the mesh (error_by_geometry.py's numpy caster); the incidence
cosine mu0 of the lamp there (0 in its shadow) and the exit cosine mu give the half-space's
exact radiance of orders >= 2 (Chandrasekhar: w (H(mu) H(mu0) - 1) / (4 (mu + mu0)) per unit
irradiance, over its flux R_ms(mu0)), and the render's orders >= 2 (OUT - SINGLE) are scaled
by that lobe at mu0 over the same lobe at normal incidence, where the table is made; pixels in
the shadow keep theirs (with `deep`: they take H(mu)'s emergent lobe of deep sources). Writes
DIR/render.exr (and scene.toml) for `translucent compare`. An estimate, not a model: the
lobe is taken at each pixel's own incidence, where the light it gives back entered nearby.
"""
import sys, pathlib, importlib.util, tomllib, numpy as np, OpenEXR
spec = importlib.util.spec_from_file_location("ebg", pathlib.Path(__file__).parent / "error_by_geometry.py")
ebg = importlib.util.module_from_spec(spec); spec.loader.exec_module(ebg)
render_path, single_path, out_dir = pathlib.Path(sys.argv[1]), sys.argv[2], pathlib.Path(sys.argv[3])
mode = sys.argv[4] if len(sys.argv) > 4 else "keep"
scene = tomllib.loads((render_path.parent / "scene.toml").read_text())
render, single = ebg.load(render_path), ebg.load(single_path)
h, w = render.shape[:2]
v, f, vn, varea = ebg.mesh()
dirs, hit, bary, corners, x, n, light, shadowed = ebg.visible(scene, render, v, f, vn)
mu0 = np.clip(n @ light, 0, 1) * ~shadowed
muo = np.clip(np.einsum("ij,ij->i", n, -dirs[hit]), 1e-3, 1)
# The two truth bunnies' presets (sigma_s', sigma_a per channel, 1/mm), as
# src/physics/material.rs has them.
PRESETS = {
    "skimmilk": ([0.70, 1.22, 1.90], [0.0014, 0.0025, 0.0142]),
    "marble": ([2.19, 2.62, 3.00], [0.0021, 0.0041, 0.0071]),
}
preset = scene.get("material", {}).get("preset")
if preset not in PRESETS:
    sys.exit(f"material preset {preset!r}: only {', '.join(PRESETS)} are known here")
sig_s, sig_a = (np.array(x) for x in PRESETS[preset])
alb = sig_s / (sig_s + sig_a)
def hfun(wa, nq=128):
    xq, wq = np.polynomial.legendre.leggauss(nq); xq = (xq + 1) / 2; wq = wq / 2
    H = np.ones(nq)
    for _ in range(5000):
        Hn = 1 / (1 - (wa / 2) * xq * np.sum(wq * H / (xq[:, None] + xq[None, :]), axis=1))
        if np.max(abs(Hn - H)) < 1e-12: break
        H = Hn
    return lambda mu: 1 / (1 - (wa / 2) * mu * np.sum(wq * H / (mu[..., None] + xq), axis=-1)) if np.ndim(mu) else 1 / (1 - (wa / 2) * mu * np.sum(wq * H / (mu + xq)))
fac = np.ones((len(x), 3))
for c in range(3):
    wa = alb[c]; H = hfun(wa)
    def rms(m0): return 1 - H(m0) * np.sqrt(1 - wa) - (wa / 2) * (1 - m0 * np.log(1 + 1 / m0))
    def lobe(mo, m0): return wa * (H(mo) * H(m0) - 1) / (4 * (mo + m0)) / rms(m0)
    lit = mu0 > 1e-3
    m0 = np.where(lit, mu0, 1.0)
    fc = lobe(muo, m0) / lobe(muo, np.ones_like(muo))
    if mode == "deep":
        # in shadow: the emergent distribution of deep sources, H(mu) normalised to unit flux
        xq = np.linspace(0.0005, 0.9995, 1000); mom = np.mean(H(xq) * 2 * xq)
        fc = np.where(lit, fc, (H(muo) / mom) / lobe(muo, np.ones_like(muo)))
    fac[:, c] = fc
full = np.ones((h * w, 3)); full[hit] = fac
full = full.reshape(h, w, 3)
out = render.copy()
out[..., :3] = single[..., :3] + (render[..., :3] - single[..., :3]) * full
out_dir.mkdir(parents=True, exist_ok=True)
OpenEXR.File({'compression': OpenEXR.ZIP_COMPRESSION, 'type': OpenEXR.scanlineimage}, {'RGBA': out.astype(np.float32)}).write(str(out_dir / "render.exr"))
(out_dir / "scene.toml").write_text((render_path.parent / "scene.toml").read_text())
print("mean factor on lit pixels", [round(full[..., c][full[..., c] != 1].mean(), 4) for c in range(3)])
