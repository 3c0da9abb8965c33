"""Builds test scenes with Blender (as a Python module) and exports them with Blender's
own glTF exporter, the one artists use. Not run by CI; the exported files are committed.

    python3.11 -m venv /tmp/bpy && /tmp/bpy/bin/pip install bpy
    /tmp/bpy/bin/python scenes/blender/make_blender_fixtures.py

Writes, beside this script:
- default-lights-on.glb   Blender's startup scene (cube, 1000 W point light, 16:9 camera)
- default-lights-off.glb  the same exported without lights (glTF viewers light it anyway)
- sun.glb                 the cube on a ground plane under a Sun (directional light)
- spotlit-prism.glb       10 m stage: a 10° spot through an N-SF11 prism (custom property
                          prismap = {"glass": "N-SF11"}), Suzanne, a dim emissive panel
- textured-glass.glb      a cube with an image texture (a generated 8×8 checker, packed),
                          a smooth-shaded N-SF11 glass sphere, under a Sun
- rough-materials.glb     under a Sun and a point light: a rough gold sphere (metallic 1,
                          roughness 0.35), a rough glass sphere (transmission 1, roughness
                          0.3), a thick green glass slab (Volume Absorption: exported as
                          KHR_materials_volume) and a smooth silver mirror, on a grey floor
- vertex-painted.glb      under a Sun, a smooth ico sphere whose colour attribute (linear
                          float colours, one per vertex: a red-green-blue gradient over
                          its position) feeds the Base Color through a Color Attribute
                          node (exported as COLOR_0), beside a cube painted one colour per
                          face (corner domain), on a grey ground
- cut-out-leaves.glb      under a Sun, a 2 m "leaf" plane whose packed RGBA image has
                          round holes (alpha 0 inside circles), its alpha through a Math
                          Greater Than 0.5 node into Alpha: exported as alphaMode MASK
                          with alphaCutoff 0.5; the holes let sunlight onto the ground
- normal-mapped.glb       under a low Sun, a 4 m plane whose packed 64×64 normal map (a
                          Normal Map node, tangent space) encodes ridges running along v,
                          h = sin(8πu): exported as normalTexture, with tangents

One fixture alone: give its name, e.g. `... make_blender_fixtures.py vertex-painted`.
"""
import math
import os

import bpy

HERE = os.path.dirname(os.path.abspath(__file__))


def startup():
    bpy.ops.wm.read_factory_settings(use_empty=False)


def export(name, lights=True, tangents=False):
    bpy.ops.export_scene.gltf(
        filepath=os.path.join(HERE, name),
        export_tangents=tangents,
        export_format="GLB",
        export_lights=lights,
        export_cameras=True,
        export_extras=True,
        export_apply=True,
        export_yup=True,
    )
    print("wrote", name)


def add_sun(energy, rotation):
    """A Sun of `energy` W/m² (exported as lux) turned by the Euler angles `rotation`."""
    sun = bpy.data.lights.new("Sun", type="SUN")
    sun.energy = energy
    obj = bpy.data.objects.new("Sun", sun)
    obj.rotation_euler = rotation
    bpy.context.collection.objects.link(obj)


def material(name, rgb, roughness=0.8):
    m = bpy.data.materials.new(name)
    m.use_nodes = True
    b = m.node_tree.nodes["Principled BSDF"]
    b.inputs["Base Color"].default_value = (*rgb, 1.0)
    b.inputs["Roughness"].default_value = roughness
    return m


def default_scenes():
    startup()
    export("default-lights-on.glb", lights=True)
    export("default-lights-off.glb", lights=False)


def sun_scene():
    startup()
    bpy.data.objects.remove(bpy.data.objects["Light"])
    bpy.ops.mesh.primitive_plane_add(size=20, location=(0, 0, -1))
    bpy.context.object.data.materials.append(material("ground", (0.5, 0.5, 0.5)))
    add_sun(3.0, (math.radians(40), math.radians(20), math.radians(30)))
    export("sun.glb")


def spotlit_prism():
    startup()
    for n in ("Cube", "Light"):
        bpy.data.objects.remove(bpy.data.objects[n])
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = 1920, 1080
    # Stage: 10 m floor and a back wall.
    bpy.ops.mesh.primitive_plane_add(size=10, location=(0, 0, 0))
    bpy.context.object.data.materials.append(material("floor", (0.8, 0.8, 0.8)))
    bpy.ops.mesh.primitive_plane_add(size=10, location=(0, 5, 5), rotation=(math.radians(90), 0, 0))
    bpy.context.object.data.materials.append(material("wall", (0.5, 0.5, 0.5)))
    # The prism: a 3-sided cylinder, 0.6 m across, 1 m tall.
    bpy.ops.mesh.primitive_cylinder_add(vertices=3, radius=0.35, depth=1.0, location=(0, 0, 0.5))
    prism = bpy.context.object
    prism.name = "Prism"
    glass = material("N-SF11 glass", (1, 1, 1), roughness=0.0)
    bsdf = glass.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Transmission Weight"].default_value = 1.0
    bsdf.inputs["IOR"].default_value = 1.78
    glass["prismap"] = {"glass": "N-SF11"}  # exported with "Custom Properties" (export_extras)
    prism.data.materials.append(glass)
    # Suzanne, smooth-shaded, beside it.
    bpy.ops.mesh.primitive_monkey_add(size=0.8, location=(-1.6, 0.6, 0.45))
    bpy.ops.object.shade_smooth()
    bpy.context.object.data.materials.append(material("suzanne", (0.7, 0.3, 0.2)))
    # A 10° spot aimed through the prism at the floor.
    spot = bpy.data.lights.new("Spot", type="SPOT")
    spot.energy = 2000.0
    spot.spot_size = math.radians(10.0)
    spot.spot_blend = 0.15
    obj = bpy.data.objects.new("Spot", spot)
    obj.location = (2.5, -1.0, 1.4)
    direction = (-2.5, 1.0, -0.9)
    obj.rotation_euler = direction_to_euler(direction)
    bpy.context.collection.objects.link(obj)
    # A dim emissive panel overhead.
    bpy.ops.mesh.primitive_plane_add(size=2, location=(0, 0, 4), rotation=(math.radians(180), 0, 0))
    panel = material("dim panel", (0.8, 0.8, 0.8))
    b = panel.node_tree.nodes["Principled BSDF"]
    b.inputs["Emission Color"].default_value = (1, 1, 1, 1)
    b.inputs["Emission Strength"].default_value = 0.5
    bpy.context.object.data.materials.append(panel)
    cam = bpy.data.objects["Camera"]
    cam.location = (0.5, -6.0, 3.0)
    cam.rotation_euler = direction_to_euler((-0.5, 6.0, -2.6))
    export("spotlit-prism.glb")


def textured_glass():
    startup()
    bpy.data.objects.remove(bpy.data.objects["Light"])
    cube = bpy.data.objects["Cube"]
    cube.location = (-1.5, 0, 0)
    img = bpy.data.images.new("checker", 8, 8)
    px = []
    for y in range(8):
        for x in range(8):
            on = (x + y) % 2 == 0
            px += [0.9, 0.2, 0.1, 1.0] if on else [0.1, 0.3, 0.8, 1.0]
    img.pixels = px
    img.pack()
    m = material("checker", (1, 1, 1))
    tex = m.node_tree.nodes.new("ShaderNodeTexImage")
    tex.image = img
    tex.interpolation = "Closest"
    m.node_tree.links.new(tex.outputs["Color"], m.node_tree.nodes["Principled BSDF"].inputs["Base Color"])
    cube.data.materials.clear()
    cube.data.materials.append(m)
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.8, location=(1.2, 0, 0), segments=32, ring_count=16)
    bpy.ops.object.shade_smooth()
    glass = material("N-SF11 glass", (1, 1, 1), roughness=0.0)
    bsdf = glass.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Transmission Weight"].default_value = 1.0
    bsdf.inputs["IOR"].default_value = 1.78
    glass["prismap"] = {"glass": "N-SF11"}
    bpy.context.object.data.materials.append(glass)
    bpy.ops.mesh.primitive_plane_add(size=20, location=(0, 0, -1))
    bpy.context.object.data.materials.append(material("ground", (0.6, 0.6, 0.6)))
    add_sun(3.0, (math.radians(30), math.radians(15), 0))
    export("textured-glass.glb")


def rough_materials():
    startup()
    bpy.data.objects.remove(bpy.data.objects["Cube"])
    light = bpy.data.objects["Light"]
    light.location = (2.0, -2.0, 3.0)
    bpy.ops.mesh.primitive_plane_add(size=12, location=(0, 0, 0))
    bpy.context.object.data.materials.append(material("floor", (0.5, 0.5, 0.5)))

    def sphere(name, loc):
        bpy.ops.mesh.primitive_uv_sphere_add(radius=0.6, location=loc, segments=48, ring_count=24)
        bpy.ops.object.shade_smooth()
        bpy.context.object.name = name
        return bpy.context.object

    gold = material("rough gold", (1.0, 0.71, 0.29), roughness=0.35)
    gold.node_tree.nodes["Principled BSDF"].inputs["Metallic"].default_value = 1.0
    sphere("Gold", (-1.4, 0, 0.6)).data.materials.append(gold)

    frosted = material("frosted glass", (1, 1, 1), roughness=0.3)
    bsdf = frosted.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Transmission Weight"].default_value = 1.0
    bsdf.inputs["IOR"].default_value = 1.5
    sphere("Frosted", (0.0, 0, 0.6)).data.materials.append(frosted)

    # A thick green slab: Volume Absorption (colour, density) in the volume socket; the
    # exporter writes KHR_materials_volume (attenuation distance = 1 / density).
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(1.5, 0, 0.5))
    slab = bpy.context.object
    slab.scale = (0.5, 1.2, 1.0)
    green = material("thick green glass", (1, 1, 1), roughness=0.0)
    bsdf = green.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Transmission Weight"].default_value = 1.0
    bsdf.inputs["IOR"].default_value = 1.5
    nodes, links = green.node_tree.nodes, green.node_tree.links
    absorb = nodes.new("ShaderNodeVolumeAbsorption")
    absorb.inputs["Color"].default_value = (0.2, 0.8, 0.3, 1.0)
    absorb.inputs["Density"].default_value = 2.0
    links.new(absorb.outputs["Volume"], nodes["Material Output"].inputs["Volume"])
    # Blender's glTF settings node carries the thickness KHR_materials_volume needs.
    group = bpy.data.node_groups.get("glTF Material Output") or bpy.data.node_groups.new(
        "glTF Material Output", "ShaderNodeTree")
    if "Thickness" not in [i.name for i in group.interface.items_tree]:
        group.interface.new_socket("Thickness", in_out="INPUT", socket_type="NodeSocketFloat")
    out = nodes.new("ShaderNodeGroup")
    out.node_tree = group
    out.inputs["Thickness"].default_value = 0.5
    slab.data.materials.append(green)

    bpy.ops.mesh.primitive_plane_add(size=1.6, location=(0, 1.6, 0.9), rotation=(math.radians(90), 0, 0))
    silver = material("silver mirror", (0.97, 0.96, 0.91), roughness=0.0)
    silver.node_tree.nodes["Principled BSDF"].inputs["Metallic"].default_value = 1.0
    bpy.context.object.data.materials.append(silver)

    add_sun(2.0, (math.radians(35), math.radians(-20), math.radians(20)))
    cam = bpy.data.objects["Camera"]
    cam.location = (0.0, -5.5, 2.4)
    cam.rotation_euler = direction_to_euler((0.0, 5.5, -1.9))
    export("rough-materials.glb")


def painted_material(name, layer):
    m = material(name, (1, 1, 1))
    node = m.node_tree.nodes.new("ShaderNodeVertexColor")
    node.layer_name = layer
    m.node_tree.links.new(node.outputs["Color"], m.node_tree.nodes["Principled BSDF"].inputs["Base Color"])
    return m


def vertex_painted():
    startup()
    bpy.data.objects.remove(bpy.data.objects["Light"])
    # The default cube, one colour per face (corner domain: each face's corners alike).
    cube = bpy.data.objects["Cube"]
    cube.location = (-1.6, 0, 0)
    cube.scale = (0.7, 0.7, 0.7)
    faces = [(0.8, 0.1, 0.1), (0.1, 0.6, 0.1), (0.1, 0.2, 0.7), (0.7, 0.7, 0.2), (0.6, 0.2, 0.6), (0.2, 0.6, 0.6)]
    mesh = cube.data
    attr = mesh.color_attributes.new(name="FacePaint", type="FLOAT_COLOR", domain="CORNER")
    for poly in mesh.polygons:
        for li in poly.loop_indices:
            attr.data[li].color = (*faces[poly.index % len(faces)], 1.0)
    cube.data.materials.clear()
    cube.data.materials.append(painted_material("face paint", "FacePaint"))
    # A smooth ico sphere with a colour per vertex: a gradient over its position.
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=3, radius=0.9, location=(1.2, 0, 0))
    bpy.ops.object.shade_smooth()
    sphere = bpy.context.object
    attr = sphere.data.color_attributes.new(name="Gradient", type="FLOAT_COLOR", domain="POINT")
    for v in sphere.data.vertices:
        x, y, z = (c / 0.9 for c in v.co)
        attr.data[v.index].color = (0.5 + 0.4 * x, 0.5 + 0.4 * y, 0.5 + 0.4 * z, 1.0)
    sphere.data.materials.append(painted_material("gradient paint", "Gradient"))
    bpy.ops.mesh.primitive_plane_add(size=20, location=(0, 0, -1))
    bpy.context.object.data.materials.append(material("ground", (0.5, 0.5, 0.5)))
    add_sun(3.0, (math.radians(30), math.radians(15), 0))
    export("vertex-painted.glb")


def cut_out_leaves():
    startup()
    for n in ("Cube", "Light"):
        bpy.data.objects.remove(bpy.data.objects[n])
    size = 32
    img = bpy.data.images.new("holes", size, size, alpha=True)
    px = []
    for y in range(size):
        for x in range(size):
            # Four round holes of radius 5 texels in a green sheet.
            hole = any((x - cx) ** 2 + (y - cy) ** 2 < 25 for cx in (8, 24) for cy in (8, 24))
            px += [0.1, 0.5, 0.1, 0.0 if hole else 1.0]
    img.pixels = px
    img.pack()
    m = material("leaf", (1, 1, 1))
    nodes, links = m.node_tree.nodes, m.node_tree.links
    tex = nodes.new("ShaderNodeTexImage")
    tex.image = img
    tex.interpolation = "Closest"
    bsdf = nodes["Principled BSDF"]
    links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    clip = nodes.new("ShaderNodeMath")
    clip.operation = "GREATER_THAN"
    clip.inputs[1].default_value = 0.5
    links.new(tex.outputs["Alpha"], clip.inputs[0])
    links.new(clip.outputs["Value"], bsdf.inputs["Alpha"])
    bpy.ops.mesh.primitive_plane_add(size=2, location=(0, 0, 1.2))
    bpy.context.object.data.materials.append(m)
    bpy.ops.mesh.primitive_plane_add(size=20, location=(0, 0, 0))
    bpy.context.object.data.materials.append(material("ground", (0.6, 0.6, 0.6)))
    add_sun(3.0, (math.radians(10), 0, 0))
    cam = bpy.data.objects["Camera"]
    cam.location = (0.0, -4.0, 3.5)
    cam.rotation_euler = direction_to_euler((0.0, 4.0, -3.2))
    export("cut-out-leaves.glb")


def normal_mapped():
    startup()
    for n in ("Cube", "Light"):
        bpy.data.objects.remove(bpy.data.objects[n])
    size = 64
    img = bpy.data.images.new("ridges", size, size, alpha=False, float_buffer=True)
    img.colorspace_settings.name = "Non-Color"
    px = []
    for y in range(size):
        for x in range(size):
            u = (x + 0.5) / size
            slope = 0.6 * math.cos(8 * math.pi * u)  # dh/du, scaled
            nx, nz = -slope, 1.0
            norm = math.hypot(nx, nz)
            px += [0.5 + 0.5 * nx / norm, 0.5, 0.5 + 0.5 * nz / norm, 1.0]
    img.pixels = px
    img.pack()
    m = material("ridged", (0.8, 0.8, 0.8))
    nodes, links = m.node_tree.nodes, m.node_tree.links
    tex = nodes.new("ShaderNodeTexImage")
    tex.image = img
    nmap = nodes.new("ShaderNodeNormalMap")
    links.new(tex.outputs["Color"], nmap.inputs["Color"])
    links.new(nmap.outputs["Normal"], nodes["Principled BSDF"].inputs["Normal"])
    bpy.ops.mesh.primitive_plane_add(size=4, location=(0, 0, 0))
    bpy.context.object.data.materials.append(m)
    add_sun(3.0, (0, math.radians(60), 0))
    cam = bpy.data.objects["Camera"]
    cam.location = (0.0, -4.0, 4.0)
    cam.rotation_euler = direction_to_euler((0.0, 4.0, -4.0))
    # With its TANGENT attribute, which the validator asks of a normal-mapped mesh (and
    # which the test compares with the frame prismap builds without it).
    export("normal-mapped.glb", tangents=True)


def direction_to_euler(d):
    from mathutils import Vector
    return Vector(d).to_track_quat("-Z", "Y").to_euler()


FIXTURES = {
    "default-lights": default_scenes,
    "sun": sun_scene,
    "spotlit-prism": spotlit_prism,
    "textured-glass": textured_glass,
    "rough-materials": rough_materials,
    "vertex-painted": vertex_painted,
    "cut-out-leaves": cut_out_leaves,
    "normal-mapped": normal_mapped,
}

if __name__ == "__main__":
    import sys

    for name in sys.argv[1:] or FIXTURES:
        FIXTURES[name]()
