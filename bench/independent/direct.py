"""A third, closed-form answer for direct lighting: single-bounce radiance
per pixel from the polygon-to-point form factor (Lambert's contour
formula), to tell which of two renderers is right when they disagree.

    python3 bench/independent/direct.py SCENE IMAGE.exr [IMAGE.exr ...]

For a Lambertian point x with normal n and reflectance rho, lit by a
polygonal emitter of radiance Le wholly visible and wholly above x's tangent
plane, the reflected radiance after one bounce is rho * Le * F, with the
point-to-polygon form factor

    F = 1/(2 pi) * | sum_i  angle(r_i, r_i+1) * n . unit(r_i x r_i+1) |

(r_i: unit vectors from x to the polygon's vertices; Lambert 1760, see
data/ground-truth.md).  The IMAGES must hold direct lighting only: radpt
`--max-depth 1`, Cycles `--max-bounces 0`.  Pixels are compared where every
one of 4 x 4 sub-pixel rays hits the front of the same reflecting surface and
the emitter is fully in view (5 x 5 shadow rays to each emitter face from
each of 2 x 2 sub-pixel points); the analytic value is the mean of the 2 x 2
sub-pixel points.  The table gives, per surface, the analytic mean and each
image's relative difference from it.

Supports what cycles.py's parser supports; the emitters must be planar.
Needs numpy (Debian python3-numpy).
"""

import math
import os
import sys

import numpy as np

sys.dont_write_bytecode = True  # no __pycache__ in the tree
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from cycles import Scene, SceneError, cast, camera_rays, read_exr, rgb_planes, surface_map, triangles  # noqa: E402


def polygon_factor(x, n, poly):
    """Point-to-polygon form factor for points x (N, 3) with normals n (N, 3)."""
    r = poly[None, :, :] - x[:, None, :]
    with np.errstate(all="ignore"):
        r /= np.linalg.norm(r, axis=2)[:, :, None]
    f = np.zeros(len(x))
    for i in range(len(poly)):
        a, b = r[:, i], r[:, (i + 1) % len(poly)]
        c = np.cross(a, b)
        cn = np.linalg.norm(c, axis=1)
        ang = np.arccos(np.clip(np.einsum("ij,ij->i", a, b), -1, 1))
        f += ang * np.einsum("ij,ij->i", n, c) / np.where(cn > 0, cn, 1)
    return np.abs(f) / (2 * math.pi)


def main(argv):
    if len(argv) < 2:
        print(__doc__.split("\n\n")[1], file=sys.stderr)
        return 2
    scene = Scene()
    try:
        scene.parse(argv[0])
        scene.check(argv[0])
    except SceneError as e:
        print(f"direct.py: {e}", file=sys.stderr)
        return 2
    T, info = triangles(scene)
    emitters = [(s, np.array(v, dtype=float), np.array(scene.materials[m][1]))
                for s, m, v in scene.faces if max(scene.materials[m][1]) > 0]
    for s, v, _ in emitters:
        n = np.cross(v[1] - v[0], v[-1] - v[0])
        n /= np.linalg.norm(n)
        if np.max(np.abs((v - v[0]) @ n)) > 1e-6 * np.max(np.ptp(v, axis=0)):
            print(f"direct.py: emitter {s} is not planar", file=sys.stderr)
            return 2
    w, h = scene.camera["size"]
    ys, xs = np.mgrid[0:h, 0:w]
    xs, ys = xs.ravel().astype(float), ys.ravel().astype(float)
    npix = w * h
    extent = float(np.max(T.reshape(-1, 3).max(0) - T.reshape(-1, 3).min(0)))
    eps = 1e-7 * extent

    names, surf, _ = surface_map(scene)
    tri_front_n = np.array([n for _, _, n in info])
    emitting = {names.index(s) for s, _, _ in emitters}
    ok = (surf >= 0) & ~np.isin(surf, list(emitting))

    # Analytic direct radiance at 2 x 2 sub-pixel points.
    L = np.zeros((npix, 3))
    g = (np.arange(5) + 0.5) / 5
    for sy in range(2):
        for sx in range(2):
            o, d = camera_rays(scene, xs + (sx + 0.5) / 2, ys + (sy + 0.5) / 2)
            t, idx = cast(T, o, d, 0, np.inf)
            x = o + d * t[:, None]
            n = tri_front_n[np.maximum(idx, 0)]
            rho = np.array([scene.materials[info[i][1]][0] if i >= 0 else [0, 0, 0] for i in idx])
            for s, v, le in emitters:
                above = np.all(np.einsum("pkj,pj->pk", v[None, :, :] - x[:, None, :], n) > eps, axis=1)
                ok &= above
                # visibility: 5 x 5 shadow rays to points of the emitter face
                # (bilinear over a quad, folded for a triangle)
                pts = []
                for a in g:
                    for b in g:
                        if len(v) == 4:
                            pts.append(v[0] + a * (v[1] - v[0]) + b * (v[3] - v[0]))
                        elif a + b < 1:
                            pts.append(v[0] + a * (v[1] - v[0]) + b * (v[2] - v[0]))
                k = np.where(ok)[0]
                for q in pts:
                    dd = q[None, :] - x[k]
                    dist = np.linalg.norm(dd, axis=1)
                    dd /= dist[:, None]
                    _, hit = cast(T, x[k], dd, eps, dist - eps)
                    blocked = hit >= 0
                    ok[k[blocked]] = False
                    k = k[~blocked]
                L += rho * le[None, :] * polygon_factor(x, n, v)[:, None] / 4
    print(f"direct.py: {argv[0]}: {int(ok.sum())} of {npix} pixels fully covered and fully lit")
    imgs = []
    for path in argv[1:]:
        _, _, planes = read_exr(path)
        imgs.append(np.stack(rgb_planes(path, planes, scene.bands == "grey"), -1).reshape(-1, 3))
    labels = [os.path.basename(p) for p in argv[1:]]
    print(f"{'surface':<16} {'pixels':>6} {'analytic':>10} " + " ".join(f"{lab[:22]:>24}" for lab in labels))
    for k, nm in enumerate(names + ["ALL"]):
        m = ok & (surf == k) if nm != "ALL" else ok
        if not m.any():
            continue
        a = L[m].mean(0)
        rel = [(img[m].mean(0) / a - 1) for img in imgs]
        print(f"{nm:<16} {int(m.sum()):>6} {a.mean():10.5f} " +
              " ".join(f"{'%+.3f %+.3f %+.3f%%' % tuple(100 * r):>24}" for r in rel))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
