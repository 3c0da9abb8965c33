#!/usr/bin/env python3
"""Writes the shipped glTF scenes (cornell-box, cornell-blackbody, cornell-f11, prism).

Run from anywhere: `python3 scenes/make_scenes.py`. The Cornell numbers are exactly those
of shared/scenes/cornell_box.json (mm, linear sRGB); the prism geometry is solved here so
that the light meets the prism near minimum deviation and the rainbow lands in view.
Only the Python standard library is used.
"""
import base64
import json
import math
import os
import struct

HERE = os.path.dirname(os.path.abspath(__file__))


class Gltf:
    def __init__(self):
        self.doc = {
            "asset": {"version": "2.0", "generator": "prismap scenes/make_scenes.py"},
            "scene": 0,
            "scenes": [{"nodes": []}],
            "nodes": [],
            "meshes": [],
            "materials": [],
            "accessors": [],
            "bufferViews": [],
            "buffers": [],
        }
        self.data = bytearray()
        self.used = set()

    def material(self, m):
        self.doc["materials"].append(m)
        return len(self.doc["materials"]) - 1

    def _node(self, node):
        self.doc["nodes"].append(node)
        self.doc["scenes"][0]["nodes"].append(len(self.doc["nodes"]) - 1)

    def mesh(self, name, tris, material):
        """tris: list of (v0, v1, v2), counter-clockwise seen from the front."""
        verts = [v for t in tris for v in t]
        off = len(self.data)
        for v in verts:
            self.data += struct.pack("<3f", *v)
        lo = [min(v[i] for v in verts) for i in range(3)]
        hi = [max(v[i] for v in verts) for i in range(3)]
        self.doc["bufferViews"].append({"buffer": 0, "byteOffset": off, "byteLength": 12 * len(verts)})
        self.doc["accessors"].append({
            "bufferView": len(self.doc["bufferViews"]) - 1, "componentType": 5126,
            "count": len(verts), "type": "VEC3", "min": lo, "max": hi})
        self.doc["meshes"].append({"name": name, "primitives": [{
            "attributes": {"POSITION": len(self.doc["accessors"]) - 1}, "material": material}]})
        self._node({"name": name, "mesh": len(self.doc["meshes"]) - 1})

    def camera(self, name, position, forward, up, yfov_deg, aspect=1.0):
        self.doc.setdefault("cameras", []).append({
            "name": name, "type": "perspective",
            "perspective": {"yfov": math.radians(yfov_deg), "znear": 1e-3, "aspectRatio": aspect}})
        self._node({"name": name, "camera": len(self.doc["cameras"]) - 1,
                    "translation": list(position), "rotation": look_rotation(forward, up)})

    def spot(self, name, position, direction, intensity, inner_deg, outer_deg, color=(1, 1, 1)):
        self.used.add("KHR_lights_punctual")
        lights = self.doc.setdefault("extensions", {}).setdefault("KHR_lights_punctual", {"lights": []})
        lights["lights"].append({
            "name": name, "type": "spot", "color": list(color), "intensity": intensity,
            "spot": {"innerConeAngle": math.radians(inner_deg), "outerConeAngle": math.radians(outer_deg)}})
        self._node({"name": name, "translation": list(position),
                    "rotation": look_rotation(direction, (0, 1, 0)),
                    "extensions": {"KHR_lights_punctual": {"light": len(lights["lights"]) - 1}}})

    def sun(self, name, direction, intensity, color=(1, 1, 1)):
        """A directional light (lux) shining along `direction`."""
        self.used.add("KHR_lights_punctual")
        lights = self.doc.setdefault("extensions", {}).setdefault("KHR_lights_punctual", {"lights": []})
        lights["lights"].append({"name": name, "type": "directional", "color": list(color), "intensity": intensity})
        self._node({"name": name, "rotation": look_rotation(direction, (0, 1, 0)),
                    "extensions": {"KHR_lights_punctual": {"light": len(lights["lights"]) - 1}}})

    def point(self, name, position, intensity, color=(1, 1, 1)):
        self.used.add("KHR_lights_punctual")
        lights = self.doc.setdefault("extensions", {}).setdefault("KHR_lights_punctual", {"lights": []})
        lights["lights"].append({"name": name, "type": "point", "color": list(color), "intensity": intensity})
        self._node({"name": name, "translation": list(position),
                    "extensions": {"KHR_lights_punctual": {"light": len(lights["lights"]) - 1}}})

    def write(self, path):
        while len(self.data) % 4:
            self.data += b"\0"
        self.doc["buffers"] = [{"byteLength": len(self.data),
                                "uri": "data:application/octet-stream;base64," + base64.b64encode(bytes(self.data)).decode()}]
        if self.used:
            self.doc["extensionsUsed"] = sorted(self.used)
        with open(path, "w") as f:
            json.dump(self.doc, f, indent=1)
            f.write("\n")


def sub(a, b): return tuple(x - y for x, y in zip(a, b))
def add(a, b): return tuple(x + y for x, y in zip(a, b))
def mul(a, k): return tuple(x * k for x in a)
def dot(a, b): return sum(x * y for x, y in zip(a, b))
def cross(a, b): return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])
def norm(a):
    l = math.sqrt(dot(a, a))
    return tuple(x / l for x in a)


def look_rotation(forward, up):
    """Quaternion [x, y, z, w] turning -Z to `forward` and +Y towards `up`."""
    f = norm(forward)
    r = norm(cross(f, up))
    u = cross(r, f)
    z = mul(f, -1)
    m = [[r[0], u[0], z[0]], [r[1], u[1], z[1]], [r[2], u[2], z[2]]]
    tr = m[0][0] + m[1][1] + m[2][2]
    if tr > 0:
        s = math.sqrt(tr + 1.0) * 2
        q = ((m[2][1] - m[1][2]) / s, (m[0][2] - m[2][0]) / s, (m[1][0] - m[0][1]) / s, 0.25 * s)
    elif m[0][0] > m[1][1] and m[0][0] > m[2][2]:
        s = math.sqrt(1.0 + m[0][0] - m[1][1] - m[2][2]) * 2
        q = (0.25 * s, (m[0][1] + m[1][0]) / s, (m[0][2] + m[2][0]) / s, (m[2][1] - m[1][2]) / s)
    elif m[1][1] > m[2][2]:
        s = math.sqrt(1.0 + m[1][1] - m[0][0] - m[2][2]) * 2
        q = ((m[0][1] + m[1][0]) / s, 0.25 * s, (m[1][2] + m[2][1]) / s, (m[0][2] - m[2][0]) / s)
    else:
        s = math.sqrt(1.0 + m[2][2] - m[0][0] - m[1][1]) * 2
        q = ((m[0][2] + m[2][0]) / s, (m[1][2] + m[2][1]) / s, 0.25 * s, (m[1][0] - m[0][1]) / s)
    return list(q)


def quad(p, a, b):
    """Corners p, p+a, p+a+b, p+b; front normal a × b."""
    p1, p2, p3 = add(p, a), add(add(p, a), b), add(p, b)
    return [(p, p1, p2), (p, p2, p3)]


# ---------------------------------------------------------------- Cornell box
def cornell(path, emission=None):
    # A verbatim copy of shared/scenes/cornell_box.json.
    src = json.load(open(os.path.join(HERE, "cornell_box.json")))
    g = Gltf()
    mats = {}
    for name, rgb in src["materials"].items():
        mats[name] = g.material({"name": name, "pbrMetallicRoughness": {
            "baseColorFactor": rgb + [1.0], "metallicFactor": 0.0, "roughnessFactor": 1.0}})
    for q in src["quads"]:
        g.mesh(q["name"], quad(tuple(q["p"]), tuple(q["a"]), tuple(q["b"])), mats[q["material"]])
    light = src["light"]
    rad = light["radiance_rgb"]
    strength = max(rad)
    lm = {"name": "light", "pbrMetallicRoughness": {
        "baseColorFactor": src["materials"][light["bsdf"]] + [1.0], "metallicFactor": 0.0, "roughnessFactor": 1.0},
        "emissiveFactor": [c / strength for c in rad],
        "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": strength}}}
    g.used.add("KHR_materials_emissive_strength")
    if emission:
        # Same luminance as the RGB light (the loader scales the shape to the colour's Y).
        lm["extras"] = {"prismap": {"emission": emission}}
    g.mesh("light", quad(tuple(light["p"]), tuple(light["a"]), tuple(light["b"])), g.material(lm))
    cam = src["camera"]
    fwd = sub(cam["target"], cam["origin"])
    # Square image: the horizontal field of view equals the vertical one.
    g.camera("camera", cam["origin"], fwd, cam["up"], cam["fov_deg"])
    g.write(path)


# ---------------------------------------------------------------- prism
def sellmeier(l_nm, B, C):
    l2 = (l_nm * 1e-3) ** 2
    return math.sqrt(1 + sum(b * l2 / (l2 - c) for b, c in zip(B, C)))


NSF11 = ((1.73759695, 0.313747346, 1.89878101), (0.013188707, 0.0623068142, 155.23629))


def refract(d, n, eta):
    cos_i = -dot(d, n)
    s2 = eta * eta * (1 - cos_i * cos_i)
    if s2 >= 1:
        return None
    cos_t = math.sqrt(1 - s2)
    return norm(add(mul(d, eta), mul(n, eta * cos_i - cos_t)))


# The prism's camera: (along the beam, to the side, height, vertical field of view °).
FIRST_LOOK = (1.22, 0.10, 0.28, 38.0)


def prism(path):
    side, height, lift = 0.15, 0.20, 0.001
    # Equilateral cross-section in xz, axis vertical.
    r = side / math.sqrt(3)
    corners = [(r * math.cos(math.radians(a)), r * math.sin(math.radians(a))) for a in (90, 210, 330)]
    faces = []  # (a, b, outward normal) in xz
    for i in range(3):
        a, b = corners[i], corners[(i + 1) % 3]
        mid = ((a[0] + b[0]) / 2, (a[1] + b[1]) / 2)
        nrm = norm((mid[0], 0.0, mid[1]))
        faces.append((a, b, nrm))

    def trace(o, d, lam):
        """Through the prism (2D faces, infinite height); returns exit point and direction."""
        n_glass = sellmeier(lam, *NSF11)
        inside = False
        for _ in range(4):
            best = None
            for (a, b, nrm) in faces:
                denom = dot(d, nrm)
                if abs(denom) < 1e-12:
                    continue
                t = dot(sub((a[0], 0, a[1]), o), nrm) / denom
                if t > 1e-9 and (best is None or t < best[0]):
                    p = add(o, mul(d, t))
                    # within the face segment?
                    ab = (b[0] - a[0], b[1] - a[1])
                    s = ((p[0] - a[0]) * ab[0] + (p[2] - a[1]) * ab[1]) / (ab[0] ** 2 + ab[1] ** 2)
                    if -1e-9 <= s <= 1 + 1e-9:
                        best = (t, p, nrm)
            if best is None:
                return None
            t, p, nrm = best
            if not inside:
                d = refract(d, nrm, 1 / n_glass)
                inside = True
            else:
                d2 = refract(d, mul(nrm, -1), n_glass)
                if d2 is None:
                    return None
                return p, d2
            o = p
        return None

    tilt = math.radians(10.0)
    a, b, n0 = faces[1]
    centre = ((a[0] + b[0]) / 2, lift + 0.75 * height, (a[1] + b[1]) / 2)
    best = None
    for deg10 in range(-890, 890):
        ang = math.radians(deg10 / 10)
        inward = mul(n0, -1)
        # rotate -n0 about +y by ang, then tilt downwards
        hx = inward[0] * math.cos(ang) - inward[2] * math.sin(ang)
        hz = inward[0] * math.sin(ang) + inward[2] * math.cos(ang)
        d = norm((hx * math.cos(tilt), -math.sin(tilt), hz * math.cos(tilt)))
        out = trace(sub(centre, mul(d, 1e-6)), d, 550.0)
        if out is None:
            continue
        dev = math.acos(max(-1, min(1, dot(d, out[1]))))
        if best is None or dev < best[0]:
            best = (dev, d)
    d = best[1]
    hits = {}
    for lam in (420.0, 550.0, 680.0):
        p, dout = trace(sub(centre, mul(d, 1e-6)), d, lam)
        t = -p[1] / dout[1]
        hits[lam] = add(p, mul(dout, t))
    print("prism: min deviation %.1f°, rainbow on floor from %s (680 nm) to %s (420 nm)" % (
        math.degrees(best[0]), tuple(round(v, 3) for v in hits[680.0]), tuple(round(v, 3) for v in hits[420.0])))

    g = Gltf()
    white = g.material({"name": "white floor", "pbrMetallicRoughness": {
        "baseColorFactor": [0.8, 0.8, 0.8, 1], "metallicFactor": 0.0, "roughnessFactor": 1.0}})
    wall = g.material({"name": "grey wall", "pbrMetallicRoughness": {
        "baseColorFactor": [0.5, 0.5, 0.5, 1], "metallicFactor": 0.0, "roughnessFactor": 1.0}})
    glass = g.material({"name": "N-SF11 glass", "pbrMetallicRoughness": {
        "baseColorFactor": [1, 1, 1, 1], "metallicFactor": 0.0, "roughnessFactor": 0.0},
        "extensions": {"KHR_materials_transmission": {"transmissionFactor": 1.0},
                       "KHR_materials_ior": {"ior": 1.78472},
                       "KHR_materials_dispersion": {"dispersion": round(20 / 25.68, 5)},
                       # Dispersion applies to volumes: the prism is a solid 0.15 m across.
                       "KHR_materials_volume": {"thicknessFactor": 0.15}},
        "extras": {"prismap": {"glass": "N-SF11"}}})
    g.used |= {"KHR_materials_transmission", "KHR_materials_ior", "KHR_materials_dispersion",
               "KHR_materials_volume", "KHR_materials_emissive_strength"}
    fill = g.material({"name": "dim ceiling panel", "pbrMetallicRoughness": {
        "baseColorFactor": [0.8, 0.8, 0.8, 1], "metallicFactor": 0.0, "roughnessFactor": 1.0},
        "emissiveFactor": [1, 1, 1],
        "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 0.15}}})
    g.mesh("floor", quad((-1.5, 0, 1.5), (3, 0, 0), (0, 0, -3)), white)
    g.mesh("back wall", quad((-1.5, 0, -1.0), (3, 0, 0), (0, 1.5, 0)), wall)
    g.mesh("ceiling panel", quad((-0.5, 1.6, -0.5), (1, 0, 0), (0, 0, 1)), fill)
    # The prism: three sides, top and bottom caps, outward (counter-clockwise) winding.
    tris = []
    y0, y1 = lift, lift + height
    for (a, b, _) in faces:
        tris += quad((a[0], y0, a[1]), (b[0] - a[0], 0, b[1] - a[1]), (0, y1 - y0, 0))
    c = [(x, z) for x, z in corners]
    top = [((c[0][0], y1, c[0][1]), (c[2][0], y1, c[2][1]), (c[1][0], y1, c[1][1]))]
    bottom = [((c[0][0], y0, c[0][1]), (c[1][0], y0, c[1][1]), (c[2][0], y0, c[2][1]))]
    # fix winding so that normals point out of the solid
    def outward(t, want):
        n = cross(sub(t[1], t[0]), sub(t[2], t[0]))
        return t if dot(n, want) > 0 else (t[0], t[2], t[1])
    tris = [outward(t, (nx, 0, nz)) for t, (_, _, (nx, _, nz)) in zip(tris, [f for f in faces for _ in (0, 1)])]
    tris += [outward(top[0], (0, 1, 0)), outward(bottom[0], (0, -1, 0))]
    g.mesh("prism", tris, glass)
    light_pos = sub(centre, mul(d, 0.4))
    g.spot("white spot", light_pos, d, 300.0, 0.4, 0.5)
    # Camera (the viewer's first look): from the side away from the light, low over the
    # floor, framing the glass in the foreground and the whole spectrum beyond it; 16:9.
    rainbow = hits[550.0]
    axis = norm((rainbow[0], 0, rainbow[2]))
    perp = (-axis[2], 0, axis[0])
    if dot(perp, sub(light_pos, (0, 0, 0))) > 0:
        perp = mul(perp, -1)  # look from the side away from the light
    target = add(mul(axis, 0.74 * math.hypot(rainbow[0], rainbow[2])), (0, 0.04, 0))
    cam = add(add(mul(axis, FIRST_LOOK[0]), mul(perp, FIRST_LOOK[1])), (0, FIRST_LOOK[2], 0))
    g.camera("camera", cam, sub(target, cam), (0, 1, 0), FIRST_LOOK[3], 16 / 9)
    g.write(path)


if __name__ == "__main__":
    cornell(os.path.join(HERE, "cornell-box.gltf"))
    cornell(os.path.join(HERE, "cornell-blackbody.gltf"), {"blackbody_k": 3000})
    # A narrow-band fluorescent lamp (issue #14): a smooth base under three sharp peaks,
    # the light the paper says its compact records cannot represent.
    cornell(os.path.join(HERE, "cornell-f11.gltf"), {"illuminant": "F11"})
    prism(os.path.join(HERE, "prism.gltf"))
