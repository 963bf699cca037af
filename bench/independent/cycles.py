"""Render a radpt scene (format 1) with Blender's Cycles, an independent path
tracer, and compare the result with a radpt EXR (bench/independent/README.md).

Run headless (Debian packages blender and python3-numpy):

    blender -b --factory-startup -noaudio --python bench/independent/cycles.py -- \
        SCENE -o OUT.exr [--spp N] [--seed S] [--seeds K] [--threads T]
        [--compare RADPT.exr [--tolerance T]] [--scale S] [--reuse]
        [--max-bounces B] [--no-light-sampling]

The scene is rebuilt in Blender with radpt's semantics (DESIGN.md, "Scene
files"):

* every surface is one-sided Lambertian: the front is a Diffuse BSDF
  (roughness 0, colour = reflect) plus an Emission (colour = emit, strength 1,
  which for a mesh is emitted radiance equal to the colour); the back, picked
  by Geometry > Backfacing, is black (no reflection, no emission);
* the front of a quad is the side (v1 - v0) x (v3 - v0) points to, of a
  triangle (v1 - v0) x (v2 - v0): Blender's face normal for the same vertex
  order (right-hand rule), so the vertices are passed through unchanged
  (and checked against Blender's polygon normals); a box expands to six
  quads as in geometry/scene.c (st_box);
* the camera is a pinhole at eye looking at look, image right = forward x up
  (Blender's camera X axis), vertical field of view (sensor fit VERTICAL);
* Cycles on the CPU, path tracing with next-event estimation and MIS, no
  denoising, no adaptive sampling, no clamping, light threshold 0, 1024
  bounces (--max-bounces: Cycles' 0 is radpt's --max-depth 1), a 1-pixel
  box pixel filter (radpt's pixels), black world, linear float EXR;
* coordinates are scaled uniformly so the geometry's largest extent is 1
  (--scale overrides).  Radiance does not depend on scale, but Cycles 3.4
  does: at the Cornell box's millimetres its triangle-light sampling makes
  direct lighting on the walls 0.6-1.0% too dark (README.md, measured
  against the closed form of direct.py), at unit scale it is exact.

Only the subset of format 1 the built-in scenes cornell, cube-ceiling and
furnace use is supported (bands grey|rgb; material reflect/emit with one value
or one per band; quad; triangle; box inward|outward; include; camera); any
other statement or form is refused with FILE:LINE and exit status 2.

With --seeds K the scene is rendered K times (seeds S .. S+K-1, N samples
each); OUT.exr holds their average (R, G, B) and the variance of each pixel's
mean (variance.R/G/B).  --compare reads radpt's EXR (R, G, B, or Y for a grey
scene, and variance.* when present) and prints, over all pixels and over
radpt's measured pixels (bench/reference.h), the per-channel means of both,
their standard errors and relative differences, a per-surface table, the
RMSE and an orientation check, writes OUT.json next to OUT.exr, and exits 1
when a channel mean differs by --tolerance (default 0.01) or more.  --reuse
compares an existing OUT.exr again without rendering.  Exit status: 0 agreed,
1 disagreed or failed, 2 bad input.

EXR files are read with the small reader below (scanline, uncompressed, ZIPS
or ZIP, half or float channels), which needs only numpy and zlib, so radpt's
and Cycles' files are read by one code path.
"""

import json
import math
import os
import struct
import sys
import time
import zlib

import numpy as np


class SceneError(Exception):
    pass


# ----------------------------------------------------------------- scene file


def _numbers(toks, where, what):
    out = []
    for t in toks:
        try:
            v = float(t)
        except ValueError:
            raise SceneError(f"{where}: {what}: '{t}' is not a number")
        if not math.isfinite(v):
            raise SceneError(f"{where}: {what}: '{t}' is not finite")
        out.append(v)
    return out


def _is_word(t):
    try:
        float(t)
        return False
    except ValueError:
        return True


class Scene:
    def __init__(self):
        self.bands = None          # 'grey' or 'rgb'
        self.nbands = 0
        self.materials = {}        # name -> (rho[3], Le[3])
        self.faces = []            # (surface, material, [v0, v1, v2 (, v3)])
        self.surfaces = set()
        self.camera = None

    def parse(self, path, stack=()):
        path = os.path.realpath(path)
        if path in stack:
            raise SceneError(f"{path}: included from itself")
        try:
            with open(path, encoding="utf-8") as f:
                lines = f.read().split("\n")
        except OSError as e:
            raise SceneError(f"{path}: cannot read: {e.strerror}")
        for n, line in enumerate(lines, 1):
            where = f"{path}:{n}"
            toks = line.split("#", 1)[0].split()
            if not toks:
                continue
            kw = toks[0]
            if kw == "include":
                if len(toks) != 2:
                    raise SceneError(f"{where}: 'include' takes one path")
                self.parse(os.path.join(os.path.dirname(path), toks[1]), stack + (path,))
            elif kw == "bands":
                self._bands(toks, where)
            elif kw == "material":
                self._material(toks, where)
            elif kw == "camera":
                self._camera(toks, where)
            elif kw in ("quad", "triangle", "box"):
                self._geometry(toks, where)
            else:
                raise SceneError(f"{where}: statement '{kw}' is not supported by this independent check "
                                 "(bands grey|rgb, material, camera, quad, triangle, box, include)")

    def _bands(self, toks, where):
        if self.bands is not None:
            raise SceneError(f"{where}: second 'bands' statement")
        if len(toks) != 2 or toks[1] not in ("grey", "rgb"):
            raise SceneError(f"{where}: only 'bands grey' and 'bands rgb' are supported here "
                             "(Cycles renders RGB; sampled wavelengths are not compared)")
        self.bands = toks[1]
        self.nbands = 1 if self.bands == "grey" else 3

    def _material(self, toks, where):
        if self.bands is None:
            raise SceneError(f"{where}: 'material' before 'bands'")
        if len(toks) < 3:
            raise SceneError(f"{where}: 'material' takes a name and reflect and/or emit")
        name = toks[1]
        if name in self.materials:
            raise SceneError(f"{where}: duplicate material '{name}'")
        vals = {"reflect": None, "emit": None}
        i = 2
        while i < len(toks):
            key = toks[i]
            if key not in vals:
                raise SceneError(f"{where}: material property '{key}' is not supported (reflect, emit)")
            if vals[key] is not None:
                raise SceneError(f"{where}: '{key}' given twice")
            j = i + 1
            while j < len(toks) and not _is_word(toks[j]):
                j += 1
            v = _numbers(toks[i + 1:j], where, key)
            if len(v) not in (1, self.nbands):
                raise SceneError(f"{where}: '{key}' takes 1 or {self.nbands} values here "
                                 "('spectrum' is not supported by this check)")
            if len(v) == 1:
                v = v * 3
            elif self.nbands == 1:
                v = v * 3
            vals[key] = v
            i = j
        rho = vals["reflect"] or [0.0] * 3
        le = vals["emit"] or [0.0] * 3
        if any(not (0 <= r <= 1) for r in rho):
            raise SceneError(f"{where}: reflect outside [0, 1]")
        if any(e < 0 for e in le):
            raise SceneError(f"{where}: negative emit")
        self.materials[name] = (rho, le)

    def _camera(self, toks, where):
        if self.camera is not None:
            raise SceneError(f"{where}: second 'camera' statement")
        arity = {"eye": 3, "look": 3, "up": 3, "fov": 1, "size": 2}
        cam = {}
        i = 1
        while i < len(toks):
            k = toks[i]
            if k not in arity:
                raise SceneError(f"{where}: unknown camera keyword '{k}'")
            if k in cam:
                raise SceneError(f"{where}: camera '{k}' given twice")
            v = toks[i + 1:i + 1 + arity[k]]
            if len(v) != arity[k] or any(_is_word(t) for t in v):
                raise SceneError(f"{where}: camera '{k}' takes {arity[k]} numbers")
            cam[k] = _numbers(v, where, "camera " + k)
            i += 1 + arity[k]
        missing = [k for k in arity if k not in cam]
        if missing:
            raise SceneError(f"{where}: camera lacks {', '.join(missing)}")
        if not (0 < cam["fov"][0] < 180):
            raise SceneError(f"{where}: camera fov outside (0, 180)")
        w, h = cam["size"]
        if w != int(w) or h != int(h) or w < 1 or h < 1:
            raise SceneError(f"{where}: camera size must be positive integers")
        cam["size"] = [int(w), int(h)]
        self.camera = cam

    def _geometry(self, toks, where):
        kw = toks[0]
        if len(toks) < 3:
            raise SceneError(f"{where}: '{kw}' takes a name and a material")
        surf, mat = toks[1], toks[2]
        if surf in self.surfaces:
            raise SceneError(f"{where}: duplicate surface name '{surf}'")
        if mat not in self.materials:
            raise SceneError(f"{where}: unknown material '{mat}'")
        if kw in ("quad", "triangle"):
            nv = 4 if kw == "quad" else 3
            if len(toks) != 3 + 3 * nv:
                raise SceneError(f"{where}: '{kw}' takes a name, a material and {nv} vertices")
            c = _numbers(toks[3:], where, kw)
            verts = [tuple(c[3 * i:3 * i + 3]) for i in range(nv)]
            faces = [verts]
        else:
            if len(toks) != 10 or toks[9] not in ("inward", "outward"):
                raise SceneError(f"{where}: 'box' takes a name, a material, xmin ymin zmin xmax ymax zmax "
                                 "and inward|outward")
            c = _numbers(toks[3:9], where, "box")
            if not all(c[a] < c[a + 3] for a in range(3)):
                raise SceneError(f"{where}: empty box")
            inward = toks[9] == "inward"
            # As geometry/scene.c st_box: corner (i, j, k) is i + 2 j + 4 k;
            # these faces are counter-clockwise seen from inside; outward
            # boxes take the vertices in the order 0, 3, 2, 1.
            corner = [(c[3 if k & 1 else 0], c[4 if k & 2 else 1], c[5 if k & 4 else 2]) for k in range(8)]
            table = [(0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3), (0, 1, 3, 2), (4, 6, 7, 5)]
            faces = [[corner[f[i if inward else (4 - i) % 4]] for i in range(4)] for f in table]
        for verts in faces:
            n = face_normal(verts)
            if np.linalg.norm(n) == 0:
                raise SceneError(f"{where}: degenerate face")
            self.faces.append((surf, mat, verts))
        self.surfaces.add(surf)

    def check(self, path):
        if self.bands is None:
            raise SceneError(f"{path}: no 'bands' statement")
        if self.camera is None:
            raise SceneError(f"{path}: no camera")
        if not self.faces:
            raise SceneError(f"{path}: no geometry")
        if not any(max(self.materials[m][1]) > 0 for _, m, _ in self.faces):
            raise SceneError(f"{path}: no emitter")


def face_normal(verts):
    """radpt's front normal: (v1 - v0) x (v3 - v0) for a quad, (v1 - v0) x (v2 - v0) for a triangle."""
    v = np.array(verts, dtype=float)
    return np.cross(v[1] - v[0], v[-1] - v[0])


def camera_frame(cam):
    """radpt's frame (geometry/camera.c): forward, right = forward x up, up' = right x forward."""
    eye = np.array(cam["eye"], dtype=float)
    fwd = np.array(cam["look"], dtype=float) - eye
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, np.array(cam["up"], dtype=float))
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    return eye, fwd, right, up


# ------------------------------------------------- ray casting (numpy, float64)


def triangles(scene):
    tri, info = [], []
    for s, m, v in scene.faces:
        v = np.array(v, dtype=float)
        n = np.cross(v[1] - v[0], v[-1] - v[0])
        n /= np.linalg.norm(n)
        for k in range(1, len(v) - 1):
            tri.append((v[0], v[k], v[k + 1]))
            info.append((s, m, n))
    return np.array(tri), info


def cast(T, o, d, tmin, tmax):
    """Closest hit (Moller-Trumbore) of rays o + t d, tmin < t < tmax: (t, triangle index or -1)."""
    best = np.full(len(o), np.inf)
    idx = np.full(len(o), -1)
    for i, (a, b, c) in enumerate(T):
        e1, e2 = b - a, c - a
        p = np.cross(d, e2)
        det = p @ e1
        with np.errstate(all="ignore"):
            inv = 1.0 / det
            tv = o - a
            u = np.einsum("ij,ij->i", p, tv) * inv
            q = np.cross(tv, e1)
            v = np.einsum("ij,ij->i", d, q) * inv
            t = (q @ e2) * inv
        ok = (det != 0) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > tmin) & (t < tmax) & (t < best)
        best = np.where(ok, t, best)
        idx = np.where(ok, i, idx)
    return best, idx


def camera_rays(scene, fx, fy):
    eye, fwd, right, up = camera_frame(scene.camera)
    w, h = scene.camera["size"]
    th = math.tan(math.radians(scene.camera["fov"][0]) / 2)
    d = (fwd[None, :] + right[None, :] * ((2 * fx / w - 1) * th * w / h)[:, None]
         + up[None, :] * ((1 - 2 * fy / h) * th)[:, None])
    d /= np.linalg.norm(d, axis=1)[:, None]
    return np.repeat(eye[None, :], len(d), 0), d


def surface_map(scene, sub=4):
    """Which surface each pixel shows: (surface names, int array [h * w],
    -1 where the sub x sub sub-pixel rays do not all hit the front of one
    surface (edges, back faces, background), and radpt's measured-pixel
    mask (bench/reference.c cast_mask: every sub-pixel ray hits the front of
    a surface that reflects light, i.e. is not a pure emitter))."""
    T, info = triangles(scene)
    names = []
    for s, _, _ in scene.faces:
        if s not in names:
            names.append(s)
    tri_surf = np.array([names.index(s) for s, _, _ in info])
    tri_front_n = np.array([n for _, _, n in info])
    tri_reflects = np.array([max(scene.materials[m][0]) > 0 for _, m, _ in info])
    w, h = scene.camera["size"]
    ys, xs = np.mgrid[0:h, 0:w]
    xs, ys = xs.ravel().astype(float), ys.ravel().astype(float)
    surf, same, good = None, np.ones(w * h, bool), np.ones(w * h, bool)
    for sy in range(sub):
        for sx in range(sub):
            o, d = camera_rays(scene, xs + (sx + 0.5) / sub, ys + (sy + 0.5) / sub)
            _, idx = cast(T, o, d, 0, np.inf)
            front = (idx >= 0) & (np.einsum("ij,ij->i", d, tri_front_n[np.maximum(idx, 0)]) < 0)
            sid = np.where(front, tri_surf[np.maximum(idx, 0)], -1)
            good &= front & tri_reflects[np.maximum(idx, 0)]
            if surf is None:
                surf = sid
            same &= sid == surf
    return names, np.where(same, surf, -1), good


# ------------------------------------------------------------------ EXR files

_HALF, _FLOAT, _UINT = 1, 2, 0
_LINES = {0: 1, 2: 1, 3: 16}   # NONE, ZIPS, ZIP


def _undo_zip(raw):
    """OpenEXR ZIP/ZIPS: inflate, undo the byte-delta predictor, de-interleave."""
    t = np.frombuffer(zlib.decompress(raw), dtype=np.uint8).astype(np.int64)
    if t.size == 0:
        return b""
    d = t.copy()
    d[1:] -= 128
    t = (np.cumsum(d) & 0xFF).astype(np.uint8)
    half = (t.size + 1) // 2
    out = np.empty_like(t)
    out[0::2] = t[:half]
    out[1::2] = t[half:]
    return out.tobytes()


def read_exr(path, attrs=None):
    """Returns (width, height, {channel: float64 array [height, width]}), rows
    from the top; string attributes go into the dict attrs when given."""
    with open(path, "rb") as f:
        data = f.read()
    magic, version = struct.unpack_from("<ii", data, 0)
    if magic != 20000630:
        raise ValueError(f"{path}: not an OpenEXR file")
    if version & 0x1A00:
        raise ValueError(f"{path}: tiled, deep or multi-part EXR is not supported by this reader")
    pos = 8
    channels, compression, window = None, None, None
    while True:
        end = data.index(b"\0", pos)
        name = data[pos:end].decode()
        pos = end + 1
        if not name:
            break
        end = data.index(b"\0", pos)
        typ = data[pos:end].decode()
        pos = end + 1
        size, = struct.unpack_from("<i", data, pos)
        pos += 4
        value = data[pos:pos + size]
        pos += size
        if name == "channels":
            channels, p = [], 0
            while value[p] != 0:
                e = value.index(b"\0", p)
                cname = value[p:e].decode()
                ptype, _, xs, ys = struct.unpack_from("<iB3xii", value, e + 1)
                if xs != 1 or ys != 1:
                    raise ValueError(f"{path}: subsampled channels are not supported")
                channels.append((cname, ptype))
                p = e + 1 + 16
        elif name == "compression":
            compression = value[0]
        elif name == "dataWindow":
            window = struct.unpack("<4i", value)
        elif attrs is not None and typ == "string":
            attrs[name] = value.decode("utf-8", "replace")
    if compression not in _LINES:
        raise ValueError(f"{path}: compression {compression} is not supported (NONE, ZIPS, ZIP)")
    x0, y0, x1, y1 = window
    w, h = x1 - x0 + 1, y1 - y0 + 1
    lines = _LINES[compression]
    nchunks = (h + lines - 1) // lines
    offsets = struct.unpack_from(f"<{nchunks}Q", data, pos)
    size_of = {_HALF: 2, _FLOAT: 4, _UINT: 4}
    dtype_of = {_HALF: "<f2", _FLOAT: "<f4", _UINT: "<u4"}
    planes = {c: np.zeros((h, w)) for c, _ in channels}
    row_bytes = sum(size_of[t] for _, t in channels) * w
    for off in offsets:
        y, size = struct.unpack_from("<ii", data, off)
        raw = data[off + 8:off + 8 + size]
        n = min(lines, y1 - y + 1)
        if compression != 0 and size < n * row_bytes:
            raw = _undo_zip(raw)
        if len(raw) != n * row_bytes:
            raise ValueError(f"{path}: damaged chunk at y = {y}")
        p = 0
        for r in range(n):
            for c, t in channels:
                nb = size_of[t] * w
                planes[c][y - y0 + r] = np.frombuffer(raw, dtype=dtype_of[t], count=w, offset=p)
                p += nb
    return w, h, planes


def rgb_planes(path, planes, grey):
    """The radiance planes as [R, G, B] (a grey image's Y thrice)."""
    if "R" in planes and "G" in planes and "B" in planes:
        return [planes["R"], planes["G"], planes["B"]]
    if grey and "Y" in planes:
        return [planes["Y"]] * 3
    raise ValueError(f"{path}: neither R, G, B nor Y channels (has {', '.join(sorted(planes))})")


# -------------------------------------------------------------------- Blender


def build_blender_scene(scene, spp, seed, threads, bounces=1024, light_sampling=True, scale=1.0):
    import bpy

    for obj in list(bpy.data.objects):
        bpy.data.objects.remove(obj, do_unlink=True)
    for coll in (bpy.data.meshes, bpy.data.materials, bpy.data.cameras, bpy.data.lights, bpy.data.worlds):
        for block in list(coll):
            coll.remove(block)
    sc = bpy.context.scene

    # Materials: front = Diffuse(reflect) + Emission(emit, strength 1); back = black.
    mats = {}
    for name, (rho, le) in scene.materials.items():
        m = bpy.data.materials.new("rp_" + name)
        m.use_nodes = True
        nt = m.node_tree
        for node in list(nt.nodes):
            nt.nodes.remove(node)
        out = nt.nodes.new("ShaderNodeOutputMaterial")
        out.target = "CYCLES"
        diffuse = nt.nodes.new("ShaderNodeBsdfDiffuse")
        diffuse.inputs["Color"].default_value = (rho[0], rho[1], rho[2], 1.0)
        diffuse.inputs["Roughness"].default_value = 0.0
        emission = nt.nodes.new("ShaderNodeEmission")
        emission.inputs["Color"].default_value = (le[0], le[1], le[2], 1.0)
        emission.inputs["Strength"].default_value = 1.0
        front = nt.nodes.new("ShaderNodeAddShader")
        nt.links.new(diffuse.outputs["BSDF"], front.inputs[0])
        nt.links.new(emission.outputs["Emission"], front.inputs[1])
        back = nt.nodes.new("ShaderNodeBsdfDiffuse")
        back.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
        geometry = nt.nodes.new("ShaderNodeNewGeometry")
        mix = nt.nodes.new("ShaderNodeMixShader")
        # Mix Shader: Fac 0 -> first shader (front), Fac 1 -> second (back).
        nt.links.new(geometry.outputs["Backfacing"], mix.inputs["Fac"])
        nt.links.new(front.outputs["Shader"], mix.inputs[1])
        nt.links.new(back.outputs["BSDF"], mix.inputs[2])
        nt.links.new(mix.outputs["Shader"], out.inputs["Surface"])
        if hasattr(m, "cycles") and hasattr(m.cycles, "sample_as_light"):
            m.cycles.sample_as_light = light_sampling  # next-event estimation on emitters (MIS)
        mats[name] = m

    # One mesh object per material; vertex order kept, so Blender's face
    # normal (right-hand rule) is radpt's front normal.
    for name in mats:
        verts, polys = [], []
        for _, mat, fv in scene.faces:
            if mat != name:
                continue
            polys.append(list(range(len(verts), len(verts) + len(fv))))
            verts.extend(tuple(scale * x for x in v) for v in fv)
        if not polys:
            continue
        mesh = bpy.data.meshes.new("rp_" + name)
        mesh.from_pydata(verts, [], polys)
        mesh.validate()
        mesh.update()
        for p in mesh.polygons:
            p.use_smooth = False
        mesh.materials.append(mats[name])
        obj = bpy.data.objects.new("rp_" + name, mesh)
        sc.collection.objects.link(obj)
        if hasattr(obj, "cycles"):
            for attr in ("shadow_terminator_offset", "shadow_terminator_geometry_offset"):
                if hasattr(obj.cycles, attr):
                    setattr(obj.cycles, attr, 0.0)
        # Check the orientation: Blender's polygon normals against radpt's.
        fi = 0
        for _, mat, fv in scene.faces:
            if mat != name:
                continue
            n = face_normal(fv)
            n /= np.linalg.norm(n)
            if float(np.dot(n, np.array(mesh.polygons[fi].normal))) < 0.999:
                raise RuntimeError(f"face normal mismatch in material {name}, face {fi}")
            fi += 1

    # Camera: pinhole, vertical field of view, looking down its local -Z with
    # local +X = radpt's right = forward x up and local +Y = radpt's up.
    cam = scene.camera
    eye, fwd, right, up = camera_frame(cam)
    w, h = cam["size"]
    cdata = bpy.data.cameras.new("rp_camera")
    cdata.type = "PERSP"
    cdata.sensor_fit = "VERTICAL"
    cdata.sensor_height = 24.0
    cdata.lens = 0.5 * cdata.sensor_height / math.tan(math.radians(cam["fov"][0]) / 2)
    cdata.shift_x = cdata.shift_y = 0.0
    eye = scale * eye
    allv = np.array([[scale * x for x in v] for _, _, fv in scene.faces for v in fv] + [list(eye)])
    extent = float(np.max(allv.max(axis=0) - allv.min(axis=0)))
    cdata.clip_start = 1e-6 * extent
    cdata.clip_end = 1e3 * extent
    cobj = bpy.data.objects.new("rp_camera", cdata)
    sc.collection.objects.link(cobj)
    from mathutils import Matrix
    M = Matrix.Identity(4)
    for i in range(3):
        M[i][0], M[i][1], M[i][2], M[i][3] = right[i], up[i], -fwd[i], eye[i]
    cobj.matrix_world = M
    sc.camera = cobj

    # World: black, nothing from outside.
    world = bpy.data.worlds.new("rp_world")
    world.use_nodes = True
    bg = world.node_tree.nodes.get("Background")
    bg.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    bg.inputs["Strength"].default_value = 0.0
    sc.world = world

    r = sc.render
    r.engine = "CYCLES"
    r.resolution_x, r.resolution_y, r.resolution_percentage = w, h, 100
    r.pixel_aspect_x = r.pixel_aspect_y = 1.0
    r.film_transparent = False
    r.use_compositing = False
    r.use_sequencer = False
    r.dither_intensity = 0.0
    r.use_border = False
    r.threads_mode = "FIXED" if threads > 0 else "AUTO"
    if threads > 0:
        r.threads = threads
    r.image_settings.file_format = "OPEN_EXR"
    r.image_settings.color_depth = "32"
    r.image_settings.color_mode = "RGB"
    r.image_settings.exr_codec = "ZIP"
    r.use_file_extension = False
    vs = sc.view_settings
    vs.view_transform = "Standard"
    vs.look = "None"
    vs.exposure = 0.0
    vs.gamma = 1.0
    vs.use_curve_mapping = False

    c = sc.cycles
    settings = {
        "device": "CPU",
        "progressive": "PATH",
        "samples": spp,
        "use_adaptive_sampling": False,
        "use_denoising": False,
        "seed": seed,
        "use_animated_seed": False,
        "max_bounces": bounces,
        "diffuse_bounces": bounces,
        "glossy_bounces": 1024,
        "transmission_bounces": 1024,
        "volume_bounces": 0,
        "transparent_max_bounces": 1024,
        "sample_clamp_direct": 0.0,
        "sample_clamp_indirect": 0.0,
        "light_sampling_threshold": 0.0,
        "blur_glossy": 0.0,
        "use_fast_gi": False,
        "pixel_filter_type": "BOX",
        "filter_width": 1.0,
        "film_exposure": 1.0,
        "use_layer_samples": "IGNORE",
    }
    applied = {}
    for k, v in settings.items():
        if hasattr(c, k):
            setattr(c, k, v)
            applied[k] = getattr(c, k)
    for k in ("samples", "use_adaptive_sampling", "use_denoising", "pixel_filter_type", "filter_width",
              "sample_clamp_direct", "sample_clamp_indirect", "max_bounces", "diffuse_bounces"):
        if k not in applied:
            raise RuntimeError(f"this Blender has no cycles.{k}; the settings cannot be matched")
    if hasattr(sc.view_layers[0], "cycles") and hasattr(sc.view_layers[0].cycles, "use_denoising"):
        sc.view_layers[0].cycles.use_denoising = False
    return applied


def render_once(path, seed):
    import bpy

    sc = bpy.context.scene
    sc.cycles.seed = seed
    tmp = path + f".tmp{os.getpid()}"
    sc.render.filepath = tmp
    # Blender prints a status line per sample: keep its stdout quiet while
    # rendering (errors still reach stderr).
    sys.stdout.flush()
    saved = os.dup(1)
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)
    try:
        t0 = time.time()
        bpy.ops.render.render(write_still=True)
        secs = time.time() - t0
    finally:
        sys.stdout.flush()
        os.dup2(saved, 1)
        os.close(saved)
        os.close(devnull)
    if not os.path.exists(tmp):
        raise RuntimeError(f"Blender wrote no {tmp}")
    return tmp, secs


def write_exr_float(path, planes):
    """A minimal scanline, uncompressed, 32-bit float EXR, rows from the top:
    R, G, B and, with several seeds, variance.R/G/B (the variance of each
    pixel's mean, as in radpt's references)."""
    h, w = planes["R"].shape
    names = sorted(planes)  # EXR channel lists are sorted by name

    def attr(name, typ, payload):
        return name.encode() + b"\0" + typ.encode() + b"\0" + struct.pack("<i", len(payload)) + payload

    chl = b"".join(n.encode() + b"\0" + struct.pack("<iB3xii", _FLOAT, 0, 1, 1) for n in names) + b"\0"
    header = struct.pack("<ii", 20000630, 2)
    header += attr("channels", "chlist", chl)
    header += attr("compression", "compression", bytes([0]))
    header += attr("dataWindow", "box2i", struct.pack("<4i", 0, 0, w - 1, h - 1))
    header += attr("displayWindow", "box2i", struct.pack("<4i", 0, 0, w - 1, h - 1))
    header += attr("lineOrder", "lineOrder", bytes([0]))
    header += attr("pixelAspectRatio", "float", struct.pack("<f", 1.0))
    header += attr("screenWindowCenter", "v2f", struct.pack("<2f", 0.0, 0.0))
    header += attr("screenWindowWidth", "float", struct.pack("<f", 1.0))
    header += b"\0"
    base = len(header) + 8 * h
    row = 8 + 4 * w * len(names)
    table = struct.pack(f"<{h}Q", *[base + y * row for y in range(h)])
    body = bytearray()
    for y in range(h):
        body += struct.pack("<ii", y, 4 * w * len(names))
        for n in names:
            body += planes[n][y].astype("<f4").tobytes()
    tmp = path + f".tmp{os.getpid()}"
    with open(tmp, "wb") as f:
        f.write(header + table + bytes(body))
    os.replace(tmp, path)


# ----------------------------------------------------------------- comparison


def _channel_stats(ref, rvar, cyc, cvar, mask):
    """Per channel over the masked pixels: means, their standard errors and
    the relative difference Cycles / radpt - 1.  rvar / cvar: variance of
    each pixel's mean (None: exact, or unknown).  Pixels are independent in
    both renderers, so the variance of a mean of n pixels is sum(var) / n^2."""
    n = int(mask.sum())
    out = []
    for b in range(3):
        ma, mc = float(ref[b][mask].mean()), float(cyc[b][mask].mean())
        se_a = math.sqrt(float(rvar[b][mask].sum())) / n if rvar is not None else float("nan")
        se_c = math.sqrt(float(cvar[b][mask].sum())) / n if cvar is not None else float("nan")
        rel = mc / ma - 1.0 if ma > 0 else float("nan")
        se_rel = (math.hypot(se_a / ma, se_c / mc) if ma > 0 and mc > 0 and math.isfinite(se_a)
                  else se_c / mc if mc > 0 else float("nan"))
        out.append({"radpt_mean": ma, "radpt_mean_se": se_a, "cycles_mean": mc, "cycles_mean_se": se_c,
                    "relative_difference": rel, "relative_difference_se": se_rel})
    return n, out


def compare(scene, out_exr, radpt_exr, cyc, cyc_var_of_mean, seeds_means, info):
    grey = scene.bands == "grey"
    rattrs = {}
    _, _, rp = read_exr(radpt_exr, rattrs)
    ref = rgb_planes(radpt_exr, rp, grey)
    exact = rattrs.get("radpt:kind") == "exact"
    h, w = cyc[0].shape
    if ref[0].shape != (h, w):
        raise ValueError(f"{radpt_exr}: {ref[0].shape[1]} x {ref[0].shape[0]} pixels, Cycles {w} x {h}")
    chn = ["R", "G", "B"]
    vnames = ["variance.Y"] * 3 if grey else ["variance.R", "variance.G", "variance.B"]
    # radpt's variance.* planes: the variance of each pixel's mean (none in
    # an exact reference).  Cycles': from the spread over the K seeds.
    rvar = [rp[v] for v in vnames] if all(v in rp for v in vnames) else None
    if rvar is None and exact:
        rvar = [np.zeros((h, w))] * 3   # a closed form: no error
    cvar = cyc_var_of_mean
    res = {"scene": info["scene"], "radpt_image": radpt_exr, "cycles_image": out_exr,
           "width": w, "height": h, "cycles": info}

    # radpt's measured pixels (bench/reference.h): every 4 x 4 sub-pixel ray
    # on the front of one surface that reflects light (not a pure emitter).
    names, surf, measured = surface_map(scene)
    surf = surf.reshape(h, w)
    measured = measured.reshape(h, w)
    regions = [("all pixels", np.ones((h, w), bool)), ("measured pixels", measured)]
    res["regions"] = {}
    print(f"\n{'pixels':<16} {'ch':<2} {'radpt mean':>11} {'+-se':>8} {'Cycles mean':>11} {'+-se':>8} "
          f"{'Cycles/radpt-1':>15} {'+-se':>7}")
    for label, mask in regions:
        n, st = _channel_stats(ref, rvar, cyc, cvar, mask)
        res["regions"][label] = {"pixels": n, "channels": dict(zip(chn, st))}
        for b in range(3):
            q = st[b]
            print(f"{(label if b == 0 else f'  ({n})' if b == 1 else ''):<16} {chn[b]:<2} {q['radpt_mean']:11.6f} {q['radpt_mean_se']:8.1e} "
                  f"{q['cycles_mean']:11.6f} {q['cycles_mean_se']:8.1e} {100 * q['relative_difference']:+14.3f}% "
                  f"{100 * q['relative_difference_se']:6.3f}%")
    res["channels"] = res["regions"]["all pixels"]["channels"]
    k = len(seeds_means)
    if k > 1:
        res["cycles_mean_se_from_seed_means"] = [float(np.std([m[b] for m in seeds_means], ddof=1)) / math.sqrt(k)
                                                 for b in range(3)]

    # Per surface (fully covered pixels): where a difference lives.
    res["surfaces"] = {}
    print(f"\n{'surface':<16} {'pixels':>6}  Cycles/radpt - 1 (R G B), +- se")
    for i, nm in enumerate(names):
        mask = surf == i
        if not mask.any():
            continue
        n, st = _channel_stats(ref, rvar, cyc, cvar, mask)
        res["surfaces"][nm] = {"pixels": n, "channels": dict(zip(chn, st))}
        print(f"{nm:<16} {n:>6}  " + "  ".join(
            f"{100 * q['relative_difference']:+6.2f}% +-{100 * q['relative_difference_se']:.2f}" for q in st))

    # RMSE, and what noise alone would give: sqrt(mean(var_radpt + var_cycles))
    # (radpt's variance is the i.i.d. estimate, which over-states the error
    # of its Sobol' samples, so the noise figure is an upper bound).
    d2 = sum(float(np.mean((cyc[b] - ref[b]) ** 2)) for b in range(3)) / 3
    noise = sum(float(np.mean((rvar[b] if rvar is not None else 0.0) + (cvar[b] if cvar is not None else 0.0)))
                for b in range(3)) / 3
    res["rmse"] = math.sqrt(d2)
    res["rmse_expected_from_noise"] = math.sqrt(noise)
    orient = {}
    for label, f in (("as is", lambda x: x), ("mirrored left-right", lambda x: x[:, ::-1]),
                     ("mirrored top-bottom", lambda x: x[::-1, :])):
        orient[label] = math.sqrt(sum(float(np.mean((f(cyc[b]) - ref[b]) ** 2)) for b in range(3)) / 3)
    res["rmse_orientation"] = orient
    print(f"\nRMSE {res['rmse']:.5f} (from the variance planes, noise alone: {res['rmse_expected_from_noise']:.5f}); "
          "orientation check, RMSE against the Cycles image " +
          ", ".join(f"{k2} {v:.4f}" for k2, v in orient.items()))
    worst = max(abs(q["relative_difference"]) for r in res["regions"].values() for q in r["channels"].values())
    res["max_abs_relative_difference"] = worst
    res["within_1_percent"] = worst < 0.01
    print(f"largest |relative difference| of a channel mean (all or measured pixels): {100 * worst:.3f}% "
          f"({'within' if worst < 0.01 else 'NOT within'} 1%)")
    js = os.path.splitext(out_exr)[0] + ".json"
    tmp = js + f".tmp{os.getpid()}"
    with open(tmp, "w") as f:
        json.dump(res, f, indent=2)
        f.write("\n")
    os.replace(tmp, js)
    print(f"wrote {js}")
    return res


# ----------------------------------------------------------------------- main


USAGE = ("usage: blender -b --factory-startup -noaudio --python cycles.py -- SCENE -o OUT.exr "
         "[--spp N] [--seed S] [--seeds K] [--threads T] [--max-bounces B] [--no-light-sampling] [--scale S] [--compare RADPT.exr] [--tolerance T] [--reuse]")


def parse_args(argv):
    a = {"scene": None, "out": None, "spp": 256, "seed": 1, "seeds": 1, "threads": 0, "compare": None,
         "max-bounces": 1024, "no-light-sampling": False, "scale": None, "tolerance": 0.01,
         "reuse": False}
    i = 0
    while i < len(argv):
        t = argv[i]
        if t in ("-o", "--spp", "--seed", "--seeds", "--threads", "--compare", "--max-bounces", "--scale",
                 "--tolerance"):
            if i + 1 >= len(argv):
                raise SystemExit(f"{t} needs a value\n{USAGE}")
            v = argv[i + 1]
            key = {"-o": "out", "--compare": "compare"}.get(t, t[2:])
            if key in ("spp", "seed", "seeds", "threads", "max-bounces"):
                try:
                    v = int(v)
                except ValueError:
                    raise SystemExit(f"{t} takes an integer\n{USAGE}")
                if v < (0 if key in ("threads", "seed", "max-bounces") else 1):
                    raise SystemExit(f"{t} out of range\n{USAGE}")
            if key in ("scale", "tolerance"):
                try:
                    v = float(v)
                except ValueError:
                    v = -1.0
                if not (v > 0 and math.isfinite(v)):
                    raise SystemExit(f"{t} takes a positive number\n{USAGE}")
            a[key] = v
            i += 2
        elif t == "--reuse":
            a["reuse"] = True
            i += 1
        elif t == "--no-light-sampling":
            a["no-light-sampling"] = True
            i += 1
        elif t.startswith("-"):
            raise SystemExit(f"unknown option {t}\n{USAGE}")
        elif a["scene"] is None:
            a["scene"] = t
            i += 1
        else:
            raise SystemExit(f"unexpected argument {t}\n{USAGE}")
    if a["scene"] is None or a["out"] is None:
        raise SystemExit(USAGE)
    return a


def render_seeds(args, out, applied):
    """K renders with seeds S .. S+K-1; writes their average (and the
    variance of each pixel's mean) to out."""
    import bpy

    sums, sqs, means, secs = None, None, [], []
    for k in range(args["seeds"]):
        seed = args["seed"] + k
        tmp, s = render_once(out, seed)
        _, _, planes = read_exr(tmp)
        os.remove(tmp)
        img = np.stack(rgb_planes(tmp, planes, False))
        secs.append(s)
        means.append([float(img[b].mean()) for b in range(3)])
        sums = img.copy() if sums is None else sums + img
        sqs = img * img if sqs is None else sqs + img * img
        print(f"cycles.py: seed {seed}: {args['spp']} spp in {s:.1f} s; channel means " +
              " ".join(f"{m:.6f}" for m in means[-1]), flush=True)
    K = args["seeds"]
    avg = sums / K
    var_of_mean = None
    if K > 1:
        # unbiased per-pixel variance over the K renders, divided by K
        var_of_mean = np.maximum(sqs / K - avg * avg, 0.0) / (K - 1)
    planes = {"R": avg[0], "G": avg[1], "B": avg[2]}
    if var_of_mean is not None:
        planes.update({"variance." + c: var_of_mean[b] for b, c in enumerate("RGB")})
    write_exr_float(out, planes)
    print(f"cycles.py: wrote {out} ({K} x {args['spp']} spp, {sum(secs):.1f} s rendering)")
    info = {"scene": args["scene"], "blender": bpy.app.version_string, "spp_per_seed": args["spp"],
            "seeds": list(range(args["seed"], args["seed"] + K)), "total_spp": K * args["spp"],
            "render_seconds": secs, "channel_means_per_seed": means, "settings": applied}
    return avg, var_of_mean, info, means


def main():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    try:
        args = parse_args(argv)
    except SystemExit as e:
        print(e, file=sys.stderr)
        return 2
    scene = Scene()
    try:
        scene.parse(args["scene"])
        scene.check(args["scene"])
    except SceneError as e:
        print(f"cycles.py: {e}", file=sys.stderr)
        return 2
    import bpy

    if args["scale"] is None:
        # Default: the geometry's largest extent becomes 1 (see the module
        # comment: Cycles 3.4's triangle-light sampling is biased at the
        # Cornell box's millimetre scale).
        allv = np.array([v for _, _, fv in scene.faces for v in fv], dtype=float)
        args["scale"] = 1.0 / float(np.max(allv.max(axis=0) - allv.min(axis=0)))
    applied = build_blender_scene(scene, args["spp"], args["seed"], args["threads"], args["max-bounces"],
                                  not args["no-light-sampling"], args["scale"])
    print(f"cycles.py: {args['scene']}: {len(scene.faces)} faces, {len(scene.materials)} materials, "
          f"{scene.camera['size'][0]} x {scene.camera['size'][1]}, Blender {bpy.app.version_string}")
    applied["scale"] = args["scale"]
    print("cycles.py: settings " + ", ".join(f"{k}={v}" for k, v in applied.items()))
    out = os.path.abspath(args["out"])
    os.makedirs(os.path.dirname(out), exist_ok=True)
    if args["reuse"]:
        # Compare an earlier render again (its JSON keeps the render's details).
        _, _, planes = read_exr(out)
        avg = np.stack(rgb_planes(out, planes, False))
        vn = ["variance." + c for c in "RGB"]
        var_of_mean = np.stack([planes[v] for v in vn]) if all(v in planes for v in vn) else None
        info, means = {"scene": args["scene"], "reused": out}, []
        old = os.path.splitext(out)[0] + ".json"
        if os.path.exists(old):
            with open(old) as f:
                info = json.load(f).get("cycles", info)
            means = info.get("channel_means_per_seed", [])
        print(f"cycles.py: comparing the existing {out}")
    else:
        avg, var_of_mean, info, means = render_seeds(args, out, applied)
    if args["compare"]:
        try:
            res = compare(scene, out, args["compare"], [avg[0], avg[1], avg[2]], var_of_mean, means, info)
        except (OSError, ValueError) as e:
            print(f"cycles.py: {e}", file=sys.stderr)
            return 2
        if not res["max_abs_relative_difference"] < args["tolerance"]:
            print(f"cycles.py: FAILED: a channel mean differs by more than {100 * args['tolerance']:g}%",
                  file=sys.stderr)
            return 1
    return 0


if __name__ == "__main__":
    try:
        status = main()
    except Exception:  # a Blender-side failure: report it, exit 1
        import traceback
        traceback.print_exc()
        status = 1
    sys.stdout.flush()
    # Blender ignores the script's exit status unless told.
    os._exit(status)
